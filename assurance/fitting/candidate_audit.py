"""How often the core model's candidates are truly unsafe on clean scenes (a model-card figure).

A candidate is truly unsafe when its safe disc holds a forbidden ground-truth pixel at full
resolution (``assurance.campaign.truth``). The share of such candidates on clean validation scenes measures
how much work is left to the runtime monitors: near 0, the data (or the model) is too easy for the
monitors to show anything; the paper's CNN on real UAVid gave about 36%, and the project's target is
15-50% (segmentation issue).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from assurance.campaign.truth import disc_pixels
from assurance.dataio.layouts import iter_samples, read_sample_labels
from assurance.dataio.uavid import read_image
from assurance.fitting.separation import disc_scores, separation
from el.classes.labels import LabelSet
from el.geometry.config import CoreConfig
from el.landing.core import run_core
from el.segmentation.contract import labels_of

Progress = Callable[..., Iterable]

__all__ = ["candidate_audit"]


def candidate_audit(segmenter: Any, data_dir: str | Path, *, core: CoreConfig | None = None,
                    progress: Progress | None = None, evidence: bool = True) -> dict[str, Any]:
    """Segment every clean scene of ``data_dir``, find the CM's candidates, count the truly unsafe ones.

    Returns the figures recorded in a model card's ``candidates`` section: images, candidates,
    unsafe candidates and their share, the share of images whose top-ranked candidate is unsafe,
    images without any candidate, and what makes the unsafe ones unsafe (the forbidden class holding
    most of each disc's forbidden pixels, and the median share of the disc that is forbidden).
    With ``evidence``, also how well the LHD monitor's evidence (the HD patch of each candidate's
    disc) separates unsafe from safe candidates (:mod:`assurance.fitting.separation`), under ``separation``.
    Deterministic for given weights, data and core configuration. Labels are read in the palette of the
    segmenter's label set (the system's, for a network behind a class map), and its forbidden classes decide.
    """
    core = core or CoreConfig()
    labels = labels_of(segmenter)
    samples = list(iter_samples(data_dir, require_labels=True))
    if not samples:
        raise ValueError(f"{data_dir}: no labelled scenes")
    items = progress(samples, total=len(samples), desc="candidates") if progress else samples
    total = unsafe = top_unsafe = empty = 0
    by_class: Counter[str] = Counter()
    shares: list[float] = []
    rows: list[dict[str, Any]] = []
    evidence = evidence and callable(getattr(segmenter, "predict_patch", None))  # a frame-only segmenter: none
    for s in items:
        rgb, ids = read_image(s.image_path), read_sample_labels(s, labels)
        if ids.shape != rgb.shape[:2]:
            raise ValueError(f"{s.label_path}: label size {ids.shape} differs from the image {rgb.shape[:2]}")
        result = run_core(segmenter.predict_frame(rgb), (rgb.shape[1], rgb.shape[0]), core, labels=labels)
        flags = []
        for c in result.candidates:
            cause = _unsafe_cause(disc_pixels(ids, c.disc), labels)
            flags.append(cause is not None)
            if evidence:
                rows.append({"scene": s.key, "unsafe": cause is not None, **disc_scores(segmenter, rgb, c.disc)})
            if cause is not None:
                by_class[cause[0]] += 1
                shares.append(cause[1])
        total += len(flags)
        unsafe += sum(flags)
        top_unsafe += bool(flags and flags[0])
        empty += not flags
    return {
        "data": str(data_dir), "images": len(samples), "candidates": total, "unsafe": unsafe,
        "unsafe_share": unsafe / total if total else None,
        "top_unsafe_share": top_unsafe / (len(samples) - empty) if len(samples) > empty else None,
        "images_without_candidate": empty,
        "unsafe_by_class": {name: by_class[name] for name in (*labels.names, "unlabelled", "outside the image")
                            if by_class[name]},
        "median_forbidden_share": float(np.median(shares)) if shares else None,
        "core": core.to_dict(),
        **({"separation": separation(rows)} if evidence else {}),
    }


def _unsafe_cause(pixels: np.ndarray, labels: LabelSet) -> tuple[str, float] | None:
    """(forbidden class of ``labels`` with most pixels in the disc, forbidden share of the disc), or None if safe."""
    if pixels.size == 0:
        return "outside the image", 1.0
    forbidden = labels.forbidden_mask(pixels)  # an ignored (unlabelled) pixel counts as forbidden, as in the truth
    if not forbidden.any():
        return None
    top = int(np.bincount(pixels[forbidden]).argmax())
    return labels.names[top] if top < labels.num_classes else "unlabelled", float(forbidden.mean())
