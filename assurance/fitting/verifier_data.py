"""The verifier's training data: crops of the core model's candidates with the campaign's truth.

For every labelled scene of a split: the network segments the frame, the core model proposes its candidates
(``el.landing.core.run_core``), and each candidate gives one crop (``el.monitors.verifier_crop.candidate_crop``)
labelled
**unsafe** when its disc holds a forbidden ground-truth pixel (``assurance.campaign.truth.true_hazard`` = 1, the
definition the campaign judges by), with a dense auxiliary target: the share of forbidden ground-truth pixels
under each cell of a coarse grid over the crop. Hard look-alikes are mined around the candidates: ``jitter`` more
discs per candidate, moved from it by up to three radii (the core model found the ground there safe-looking too),
each with its own truth; and ``lookalikes`` discs per scene are drawn where the core model finds the ground valid (no
forbidden class within the radius, by the network) but the ground truth puts a forbidden pixel within it: the
look-alikes the network paints safe (a shared street paved like its square, a gravel track), of which the core
model's own candidates hold only the few its clustering happens to pick. Nothing here reads the segmentation
network's output besides where the candidates and the valid ground lie: the verifier learns from pixels and ground
truth.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from assurance.campaign.truth import true_hazard
from assurance.dataio.layouts import iter_samples, read_sample_labels
from assurance.dataio.uavid import Sample, read_image
from assurance.progress import progress as bar
from el.base.decision import Disc
from el.classes.labels import LabelSet
from el.geometry.config import CoreConfig
from el.landing.core import CoreResult, full_resolution, run_core
from el.monitors.verifier_crop import candidate_crop, crop_window, padded_window
from el.segmentation.contract import labels_of

JITTER_RANGES: tuple[tuple[float, float], ...] = ((0.0, 0.5), (0.5, 1.5), (1.5, 3.0))  # in radii
LOOKALIKE_RANK = -2


@dataclass
class CropSet:
    """Crops (n, size, size, 3) uint8, their truth (n,) bool, auxiliary targets (n, g, g) float32, the scene of
    each, whether each is a core-model candidate (else a mined disc), its hazard rank in its frame (-1 for a disc
    mined around a candidate, :data:`LOOKALIKE_RANK` for a look-alike disc), and the disc (x, y, r) in
    full-resolution pixels."""

    crops: np.ndarray
    unsafe: np.ndarray
    aux: np.ndarray
    scene: np.ndarray
    is_candidate: np.ndarray
    rank: np.ndarray
    discs: np.ndarray

    def save(self, path: str | Path) -> None:
        np.savez(path, **self.__dict__)

    @classmethod
    def load(cls, path: str | Path) -> CropSet:
        with np.load(path) as z:
            return cls(**{k: z[k] for k in cls.__dataclass_fields__})

    @classmethod
    def concat(cls, parts: list[CropSet]) -> CropSet:
        """The parts joined in order. The list is emptied as each part is copied, so joining a split takes little
        more memory than the split itself (600 scenes of 256 px crops are about 10 GB)."""
        if not parts:
            raise ValueError("no crops to join")
        out = {k: np.empty((sum(len(getattr(p, k)) for p in parts), *getattr(parts[0], k).shape[1:]),
                           getattr(parts[0], k).dtype) for k in cls.__dataclass_fields__}
        at = dict.fromkeys(out, 0)  # per field: spilled crops (collect_crops) are empty here
        while parts:
            part = parts.pop(0)
            for k, v in out.items():
                src = getattr(part, k)
                v[at[k]:at[k] + len(src)] = src
                at[k] += len(src)
        return cls(**out)


def aux_target(forbidden: np.ndarray, disc: Disc, *, margin: float, grid: int) -> np.ndarray:
    """The share of forbidden ground-truth pixels under each cell of a ``grid`` x ``grid`` grid over the crop
    (outside the image counts as forbidden): ndarray (grid, grid) float32."""
    x0, y0, x1, y1 = crop_window(disc, margin)
    window = padded_window(forbidden, x0, y0, x1, y1, fill=1).astype(np.float32)
    return cv2.resize(window, (grid, grid), interpolation=cv2.INTER_AREA)


def lookalike_discs(result: CoreResult, forbidden: np.ndarray, rng: np.random.Generator, n: int) -> list[Disc]:
    """Up to ``n`` discs centred on working pixels the core model found valid (``result.valid``) within their safety
    radius of a forbidden ground-truth pixel (``forbidden``, full resolution): drawn uniformly among them, without
    replacement; in full-resolution pixels, each of its row's radius (``result.radii``, mapped as the candidates
    are). The ground truth is read on the working grid (a cell is forbidden when any pixel under it is), so a drawn
    disc's own truth is computed again at full resolution."""
    (w, h), (width, height) = result.working_size, result.input_size
    if n <= 0 or result.valid is None or not result.valid.any():
        return []
    radii = result.radii
    cells = cv2.resize(forbidden.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0
    if not cells.any():
        return []
    dist = cv2.distanceTransform((~cells).astype(np.uint8), cv2.DIST_L2, 5)
    with np.errstate(invalid="ignore"):
        near = result.valid & (dist < radii[:, None])
    rows, cols = np.nonzero(near)
    if not rows.size:
        return []
    pick = np.sort(rng.choice(rows.size, size=min(n, rows.size), replace=False))
    x, y, r = full_resolution(rows[pick], cols[pick], radii[rows[pick]], (w, h), (width, height))
    return [Disc(float(a), float(b), float(c)) for a, b, c in zip(x, y, r, strict=True)]


def jittered(disc: Disc, rng: np.random.Generator, n: int, width: int, height: int) -> list[Disc]:
    """``n`` discs of the candidate's radius moved from it by a distance drawn in :data:`JITTER_RANGES` (in turn),
    their centres inside the image."""
    out = []
    for k in range(n):
        lo, hi = JITTER_RANGES[k % len(JITTER_RANGES)]
        dist = rng.uniform(lo, hi) * disc.radius_px
        angle = rng.uniform(0.0, 2.0 * math.pi)
        x = min(max(disc.x + dist * math.cos(angle), 0.5), width - 0.5)
        y = min(max(disc.y + dist * math.sin(angle), 0.5), height - 0.5)
        out.append(Disc(x, y, disc.radius_px * rng.uniform(0.9, 1.1)))
    return out


@dataclass(frozen=True, kw_only=True)
class CropSettings:
    """How a scene's crops are cut: the core model's configuration that proposes the candidates (``core``; None:
    ``CoreConfig()``), the crop's side ``size`` (px) and ``margin`` around the disc, the auxiliary target's
    ``grid`` (cells a side), ``jitter``, the discs mined around each candidate, and ``lookalikes``, the look-alike
    discs drawn per scene (:func:`lookalike_discs`)."""

    core: CoreConfig | None = None
    size: int = 96
    margin: float = 0.5
    grid: int = 24
    jitter: int = 0
    lookalikes: int = 0


def scene_crops(rgb: np.ndarray, ids: np.ndarray, segmenter: Any, *, labels: LabelSet, settings: CropSettings,
                rng: np.random.Generator, scene: int, candidates: Sequence[Any] | None = None) -> CropSet:
    """The crops of one scene's candidates (``candidates``: the core model's, found here when None), of
    ``settings.jitter`` mined discs per candidate and of ``settings.lookalikes`` look-alike discs (these need the
    core model's valid ground: ``candidates`` None)."""
    core = settings.core or CoreConfig()
    size, margin, grid, jitter = settings.size, settings.margin, settings.grid, settings.jitter
    height, width = rgb.shape[:2]
    result = None
    if candidates is None:
        result = run_core(segmenter.predict_frame(rgb), (width, height), core, labels=labels)
        candidates = result.candidates
    elif settings.lookalikes:
        raise ValueError("look-alike discs need the core model's valid ground: pass no candidates")
    forbidden = labels.forbidden_mask(ids)
    discs: list[tuple[Disc, bool, int]] = []
    for k, cand in enumerate(candidates):
        disc = Disc(float(cand.x), float(cand.y), float(cand.radius_px))
        discs.append((disc, True, k))
        discs += [(d, False, -1) for d in jittered(disc, rng, jitter, width, height)]
    if result is not None and settings.lookalikes:
        drawn = lookalike_discs(result, forbidden, rng, settings.lookalikes)
        discs += [(d, False, LOOKALIKE_RANK) for d in drawn]
    n = len(discs)
    crops = np.zeros((n, size, size, 3), np.uint8)
    aux = np.zeros((n, grid, grid), np.float32)
    unsafe = np.zeros(n, bool)
    for i, (d, _, _) in enumerate(discs):
        crops[i] = candidate_crop(rgb, d, size=size, margin=margin)
        aux[i] = aux_target(forbidden, d, margin=margin, grid=grid)
        unsafe[i] = true_hazard(ids, d, labels=labels) >= 1.0
    return CropSet(crops, unsafe, aux, np.full(n, scene, np.int64), np.array([c for _, c, _ in discs], bool),
                   np.array([k for _, _, k in discs], np.int64),
                   np.array([(d.x, d.y, d.radius_px) for d, _, _ in discs], np.float64).reshape(-1, 3))


def collect_crops(data: str | Path, segmenter: Any, *, settings: CropSettings | None = None, seed: int = 0,
                  samples: Sequence[Sample] | None = None, progress: bool = False, desc: str = "scenes",
                  spill: Path | None = None) -> CropSet:
    """Every candidate crop of the clean scenes of ``data`` (and ``settings.jitter`` mined discs per candidate), cut
    as ``settings`` says (None: :class:`CropSettings`'s defaults). ``spill``: a file the crops are written to scene
    by scene and read back from (memory-mapped, read-only), so a large training split (about 200 kB a crop at
    256 px) lies on disk, not in memory."""
    settings = settings or CropSettings()
    settings = replace(settings, core=settings.core or CoreConfig())
    if samples is None:
        samples = list(iter_samples(data, require_labels=True))
    if not samples:
        raise ValueError(f"{data}: no labelled scenes")
    labels = labels_of(segmenter)
    rng = np.random.default_rng(seed)
    parts = []
    with open(spill, "wb") if spill is not None else contextlib.nullcontext() as sink:
        for i, s in enumerate(bar(samples, total=len(samples), desc=desc, enabled=progress)):
            rgb, ids = read_image(s.image_path), read_sample_labels(s, labels)
            if ids.shape != rgb.shape[:2]:
                raise ValueError(f"{s.label_path}: label size {ids.shape} differs from the image {rgb.shape[:2]}")
            part = scene_crops(rgb, ids, segmenter, labels=labels, settings=settings, rng=rng, scene=i)
            if sink is not None:
                sink.write(np.ascontiguousarray(part.crops).tobytes())
                part = replace(part, crops=np.empty((0, *part.crops.shape[1:]), np.uint8))  # not a view: frees
            parts.append(part)
    out = CropSet.concat(parts)
    if spill is None or not len(out.unsafe):
        return out
    shape = (len(out.unsafe), *out.crops.shape[1:])
    return replace(out, crops=np.memmap(spill, dtype=np.uint8, mode="r", shape=shape))
