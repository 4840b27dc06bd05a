"""The core model (CM) after segmentation: class probabilities -> ranked, pruned landing candidates.

``run_core`` takes the softmax of the segmentation at working resolution, (8, h, w) float, and
returns the candidates in **full-resolution** pixel coordinates of the input image, ranked by
increasing hazard (docs/architecture.md sections 3.3-3.5). The classes, which of them are forbidden
and their hazard scores are a label set's (``labels``, default :data:`el.classes.labels.UAVID`, 8 classes).

Coordinates: continuous image coordinates; the full-resolution pixel at (row r, col c) covers
[c, c+1) x [r, r+1), so its centre is (c + 0.5, r + 0.5) and the image spans [0, W] x [0, H].
A working pixel (i, j) maps to the centre ((j + 0.5) W / w, (i + 0.5) H / h); a working radius
R maps to R * min(W / w, H / h) (the disc stays inside the scaled working disc).

Guarantee (EL-R01, with correct segmentation): no point of any forbidden full-resolution pixel
lies inside a candidate's disc, the disc lies inside the image, and the centre's full-resolution
row is reachable. Input that is not a finite probability map raises ValueError: the decision loop
turns it into the default action, never into candidates.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from el.base.deadline import checkpoint
from el.base.decision import Candidate, Disc
from el.classes.labels import LabelSet
from el.geometry.camera import working_size
from el.geometry.config import CoreConfig
from el.landing import candidates as cand
from el.landing import ranking
from el.landing import regions as reg
from el.landing import representatives as reps

PROB_TOLERANCE = 1e-3  # how far a probability may stray from [0, 1], and a pixel's sum from 1


@dataclass(frozen=True)
class CoreResult:
    """What the CM found.

    candidates : ranked (rank 0 = least hazardous), pruned, full-resolution coordinates, no verdicts.
    default_area : the default action's proxy landing area (full resolution).
    timings : seconds per stage: "valid_s", "regions_s", "representatives_s", "ranking_s", "total_s".
    stats : counts: valid pixels, regions, representatives before pruning, candidates.
    working_size, input_size : (width, height) of the working map and of the input image.
    first_reachable_row : first reachable full-resolution row.
    valid : (h, w) bool working-resolution valid pixels (for drawing and analysis).
    radii : (h,) float working-resolution safety radius of each row (R_px; the valid-pixel stage's).
    """

    candidates: list[Candidate]
    default_area: Disc
    timings: dict[str, float]
    stats: dict[str, int]
    working_size: tuple[int, int]
    input_size: tuple[int, int]
    first_reachable_row: int
    valid: np.ndarray = field(repr=False)
    radii: np.ndarray = field(repr=False)


def check_probs(probs: np.ndarray, input_size: tuple[int, int], working_width: int | None = None, *,
                labels: LabelSet) -> None:
    """ValueError unless ``probs`` is a finite (C, h, w) probability map (C = ``labels.num_classes``)
    whose size keeps the aspect ratio of ``input_size = (W, H)`` (and, if given, has width ``working_width``)."""
    n = labels.num_classes
    if not isinstance(probs, np.ndarray):
        raise ValueError(f"class probabilities must be a numpy array, got {type(probs).__name__}")
    if probs.ndim != 3 or probs.shape[0] != n:
        raise ValueError(f"class probabilities must have shape ({n}, h, w), got {probs.shape}")
    if not np.issubdtype(probs.dtype, np.floating):
        raise ValueError(f"class probabilities must be floating point, got {probs.dtype}")
    W, H = _check_size(input_size)
    _, h, w = probs.shape
    if working_width is not None and w != working_width:
        raise ValueError(f"class probabilities are {w} px wide, the working width is {working_width}")
    if (w, h) != working_size(W, H, w):
        raise ValueError(f"class probabilities of {w}x{h} do not keep the aspect ratio of the {W}x{H} input "
                         f"(expected {working_size(W, H, w)[0]}x{working_size(W, H, w)[1]})")
    if h < 8 or w < 8:
        raise ValueError(f"working map must be at least 8x8, got {w}x{h}")
    # Two passes: the minimum and the per-pixel sum. NaN and inf propagate into both; with every
    # value >= 0 and every sum ~1, every value is <= 1 too.
    lo = float(probs.min())
    total = probs.sum(axis=0, dtype=np.float32)
    lo_sum, hi_sum = float(total.min()), float(total.max())
    if not (math.isfinite(lo) and math.isfinite(lo_sum) and math.isfinite(hi_sum)):
        raise ValueError("class probabilities contain NaN or infinite values")
    if lo < -PROB_TOLERANCE:
        raise ValueError(f"class probabilities must lie in [0, 1], got a value of {lo:.4g} (logits?)")
    worst = max(abs(lo_sum - 1), abs(hi_sum - 1))
    if worst > PROB_TOLERANCE * n:
        raise ValueError(f"class probabilities must sum to 1 per pixel, off by up to {worst:.4g} (logits?)")


def _check_size(input_size: tuple[int, int]) -> tuple[int, int]:
    try:
        W, H = (int(v) for v in input_size)
    except (TypeError, ValueError):
        raise ValueError(f"input_size must be (width, height), got {input_size!r}") from None
    if W < 8 or H < 8:
        raise ValueError(f"input image must be at least 8x8, got {W}x{H}")
    return W, H


def reachable_working_row(
    input_size: tuple[int, int], working: tuple[int, int], config: CoreConfig
) -> tuple[int, int]:
    """(first reachable working row, first reachable full-resolution row).

    A working row counts only when it is reachable at working resolution and its centre maps to a
    reachable full-resolution row, so the rule holds in both grids.
    """
    W, H = input_size
    w, h = working
    full_first = config.geometry(W, H).first_reachable_row
    work_first = config.geometry(w, h).first_reachable_row
    sy = H / h
    # smallest i with floor((i + 0.5) * sy) >= full_first
    i = max(0, int(math.ceil(full_first / sy - 0.5)))
    while i > 0 and math.floor((i - 1 + 0.5) * sy) >= full_first:
        i -= 1
    while math.floor((i + 0.5) * sy) < full_first:
        i += 1
    return max(work_first, i), full_first


def run_core(
    probs: np.ndarray,
    input_size: tuple[int, int],
    config: CoreConfig | None = None,
    *,
    clock: Callable[[], float] = time.perf_counter,
    labels: LabelSet,
) -> CoreResult:
    """The CM post-processing: class probabilities (8, h, w) at working resolution -> candidates.

    Parameters
    ----------
    probs : ndarray of shape (8, h, w), float
        Per-pixel class probabilities (softmax) at working resolution; (w, h) must keep the aspect
        ratio of the input (``el.geometry.camera.working_size``) and w must equal ``config.working_width``.
    input_size : (W, H)
        Size of the full-resolution input image, in pixels.
    config : CoreConfig
        Parameters; defaults to ``CoreConfig()``.
    clock : callable
        Time source for the stage timings (injectable for tests).
    labels : LabelSet
        The classes of ``probs`` (its first axis), which are forbidden and their hazard scores;
        defaults to UAVid (``el.classes.labels.UAVID``).

    Returns
    -------
    CoreResult
        Candidates ranked by increasing hazard, in full-resolution coordinates.

    Raises
    ------
    ValueError
        Shape, type, finiteness or normalisation problems: never candidates from bad input.
    """
    config = config or CoreConfig()
    t0 = clock()
    check_probs(probs, input_size, config.working_width, labels=labels)
    W, H = _check_size(input_size)
    _, h, w = probs.shape
    geo = config.geometry(w, h)
    min_row, full_first = reachable_working_row((W, H), (w, h), config)

    radii = _sized_unreachable_rows(cand.row_radii(geo, config.safety, config.mode), min_row)
    forbidden = cand.forbidden_from_probs(probs, labels=labels)
    vp = cand.valid_pixels(forbidden, radii, mode=config.mode, min_row=min_row)
    t1 = clock()
    checkpoint("candidates (regions)")  # the decision's deadline between the CM's stages (el.base.deadline)

    region_fn = reg.regions_fast if config.region_method == "fast" else reg.regions_dbscan
    regions = region_fn(vp.valid, eps=config.dbscan_eps, min_samples=config.dbscan_min_samples)
    t2 = clock()
    checkpoint("candidates (representatives)")

    rows, cols, _ = reps.representatives(
        regions, n_star=config.n_star, max_points=config.kmeans_max_points,
        seed=config.kmeans_seed, n_init=config.kmeans_n_init,
    )
    t3 = clock()
    checkpoint("candidates (ranking)")

    out = _ranked_candidates(probs, vp, rows, cols, config, (W, H), labels)
    t4 = clock()
    return CoreResult(
        candidates=out,
        default_area=default_area(W, H, config),
        timings={"valid_s": t1 - t0, "regions_s": t2 - t1, "representatives_s": t3 - t2,
                 "ranking_s": t4 - t3, "total_s": t4 - t0},
        stats={"valid_pixels": int(vp.valid.sum()), "regions": int(regions.n_regions),
               "representatives": int(len(rows)), "candidates": len(out)},
        working_size=(w, h),
        input_size=(W, H),
        first_reachable_row=full_first,
        valid=vp.valid,
        radii=vp.radii,
    )


def _sized_unreachable_rows(radii: np.ndarray, min_row: int) -> np.ndarray:
    """``radii`` with the unreachable rows that see no ground (at or above the horizon: R_px 0, or NaN) given the
    first reachable row's radius: they are never valid pixels, and the valid-pixel stage wants every radius > 0."""
    bad = ~(np.isfinite(radii) & (radii > 0))
    bad[min_row:] = False
    if bad.any():
        radii = radii.copy()
        radii[bad] = radii[min_row] if min_row < len(radii) else 1.0
    return radii


def _ranked_candidates(probs: np.ndarray, vp: cand.ValidPixels, rows: np.ndarray, cols: np.ndarray,
                       config: CoreConfig, input_size: tuple[int, int], labels: LabelSet) -> list[Candidate]:
    """Rank the representatives by hazard, prune overlaps, map to full-resolution coordinates (3.5, 3.1)."""
    W, H = input_size
    _, h, w = probs.shape
    r = vp.radii[rows]
    h_s = ranking.semantic_hazard(probs, rows, cols, r, labels=labels)
    h_d = ranking.distance_hazard(vp.clearance[rows, cols], r, config.d_max_factor)
    hazard = ranking.combined_hazard(h_s, h_d, config.alpha)
    order = ranking.rank_order(hazard, rows, cols)
    kept = cand.prune_overlaps(rows, cols, r, order, config.overlap_max)
    x, y, radius = full_resolution(rows, cols, r, (w, h), input_size)
    return [
        Candidate(
            rank=rank,
            x=float(x[k]),
            y=float(y[k]),
            radius_px=float(radius[k]),
            hazard=float(hazard[k]),
            hazard_semantic=float(h_s[k]),
            hazard_distance=float(h_d[k]),
        )
        for rank, k in enumerate(kept)
    ]


def full_resolution(rows: np.ndarray, cols: np.ndarray, radii: np.ndarray, working_size: tuple[int, int],
                    input_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Working-map cells (``rows``, ``cols``) and their radii (working px) -> full-resolution centres (x, y) and
    radii: a cell's centre scaled by each axis, a radius by the smaller scale (the one mapping of both)."""
    (w, h), (W, H) = working_size, input_size
    sx, sy = W / w, H / h
    return (np.asarray(cols) + 0.5) * sx, (np.asarray(rows) + 0.5) * sy, np.asarray(radii) * min(sx, sy)


def default_area(width: int, height: int, config: CoreConfig | None = None) -> Disc:
    """The default action's proxy landing area: where opening the parachute without moving comes down.

    The nadir point in view (``CameraGeometry.nadir_y``; the image centre for a nadir camera): the disc
    there, moved up just enough to lie inside the image (basis "nadir"). Out of view (an oblique camera):
    the nearest ground in view, the bottom-centre disc tangent to the bottom edge ("nearest_ground", the
    paper's proxy). Either way the radius is the R_px of the centre's row (full-resolution geometry).
    """
    config = config or CoreConfig()
    W, H = _check_size((width, height))
    geo = config.geometry(W, H)
    nadir = geo.nadir_y
    centre = nadir if nadir < H else math.inf  # the centre's y, before it is moved inside the image
    first = H - 1.0 if math.isinf(centre) else min(max(centre - 0.5, 0.0), H - 1.0)
    r = float(geo.radius_px(np.array([first]), config.safety)[0])
    for _ in range(50):  # r = R_px(row of the centre), the centre at y = min(nadir, H - r): a fixed point
        row = min(max(min(centre, H - r) - 0.5, 0.0), H - 1.0)
        new = float(geo.radius_px(np.array([row]), config.safety)[0])
        if abs(new - r) < 1e-9:
            break
        r = new
    r = min(r, W / 2.0, H / 2.0)
    basis = "nearest_ground" if math.isinf(centre) else "nadir"
    return Disc(x=W / 2.0, y=min(centre, H - r), radius_px=r, basis=basis)


def probs_from_labels(ids: np.ndarray, size: tuple[int, int], *, labels: LabelSet) -> np.ndarray:
    """One-hot class probabilities (C, h, w) float32 at ``size = (w, h)`` from full-resolution ids of ``labels``
    (C = ``labels.num_classes``, 8 for the default UAVid).

    Conservative pooling: a working pixel that any forbidden source pixel overlaps takes a
    forbidden class (the most frequent forbidden one); the others take the most frequent class.
    """
    ids = np.asarray(ids)
    if ids.ndim != 2:
        raise ValueError(f"label map must be 2-D class ids, got shape {ids.shape}")
    if not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"label map must hold integer class ids, got {ids.dtype}")
    pooled = cand.pooled_label_ids(ids, size, labels=labels)
    w, h = size
    probs = np.zeros((labels.num_classes, h, w), dtype=np.float32)
    np.put_along_axis(probs, pooled[None].astype(np.intp), 1.0, axis=0)
    return probs
