"""Segmentation figures: confusion matrices, per-class IoU and mIoU at both scales.

The protocol (:mod:`el.segmentation.protocol`) is recorded in the model card so that ``uav-el model-card
--verify`` can redo exactly the same computation: every validation frame at the working resolution, and a
seeded set of full-resolution square patches per frame in the reachable rows
(:func:`assurance.fitting.network.data.patch_positions`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from assurance.fitting.network.data import Prepared
from el.classes.labels import CLASS_NAMES, NUM_CLASSES


def confusion(truth: np.ndarray, pred: np.ndarray, num_classes: int = NUM_CLASSES) -> np.ndarray:
    """Confusion matrix (rows = true class, columns = predicted), int64 (C, C)."""
    truth = np.asarray(truth, np.int64).ravel()
    pred = np.asarray(pred, np.int64).ravel()
    if truth.shape != pred.shape:
        raise ValueError(f"truth and prediction differ in size: {truth.shape} vs {pred.shape}")
    return np.bincount(truth * num_classes + pred, minlength=num_classes**2).reshape(num_classes, num_classes)


def iou_from_confusion(conf: np.ndarray) -> np.ndarray:
    """Per-class IoU; NaN for a class absent from both truth and prediction."""
    conf = np.asarray(conf, np.float64)
    tp = np.diag(conf)
    denom = conf.sum(0) + conf.sum(1) - tp
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(denom > 0, tp / denom, np.nan)


def summarise(conf: np.ndarray) -> dict[str, Any]:
    """mIoU (mean over classes present in truth or prediction), per-class IoU, pixel accuracy, confusion."""
    conf = np.asarray(conf, np.int64)
    iou = iou_from_confusion(conf)
    total = int(conf.sum())
    return {
        "miou": float(np.nanmean(iou)) if np.isfinite(iou).any() else None,
        "per_class_iou": {name: (None if np.isnan(v) else float(v)) for name, v in zip(CLASS_NAMES, iou, strict=True)},
        "pixel_accuracy": float(np.trace(conf) / total) if total else None,
        "pixels": total,
        "confusion": conf.tolist(),
    }


def evaluate(segmenter: Any, samples: Iterable[Prepared], *, progress: Callable[..., Iterable] | None = None,
             total: int | None = None) -> dict[str, Any]:
    """Figures of a :class:`~el.segmentation.inference.Segmenter` on prepared validation samples.

    Returns ``{"working_resolution": summary, "hd_patches": summary, "frames": n, "patches": m}``
    (summaries as :func:`summarise`).
    """
    conf_wr = np.zeros((NUM_CLASSES, NUM_CLASSES), np.int64)
    conf_hd = np.zeros_like(conf_wr)
    frames = patches = 0
    items = progress(samples, total=total, desc="evaluate") if progress is not None else samples
    for s in items:
        probs = segmenter.predict_frame(s.image)
        conf_wr += confusion(s.labels, probs.argmax(0))
        frames += 1
        if len(s.regions):
            for probs_hd, lab in zip(segmenter.predict_patches(list(s.regions)), s.region_labels, strict=True):
                conf_hd += confusion(lab, probs_hd.argmax(0))
                patches += 1
    return {"frames": frames, "patches": patches,
            "working_resolution": summarise(conf_wr), "hd_patches": summarise(conf_hd)}


def selection_score(figures: dict[str, Any]) -> float:
    """Model-selection score: the mean of the mIoU at both scales (missing figures count as 0)."""
    wr = figures["working_resolution"]["miou"] or 0.0
    hd = figures["hd_patches"]["miou"] if figures["patches"] else wr
    return 0.5 * (wr + (hd or 0.0))


def compare_figures(recorded: dict[str, Any], recomputed: dict[str, Any], *, iou_tol: float = 0.002,
                    confusion_tol: float = 1e-3) -> list[str]:
    """Differences between two evaluation results beyond tolerance, as readable lines (empty = match).

    IoU figures may differ by ``iou_tol`` (absolute); confusion matrices by ``confusion_tol`` of the
    pixel count in total absolute difference (thread scheduling may flip a handful of pixels).
    """
    problems: list[str] = []
    for scale in ("working_resolution", "hd_patches"):
        a, b = recorded.get(scale), recomputed.get(scale)
        if a is None or b is None:
            problems.append(f"{scale}: missing in {'recorded' if a is None else 'recomputed'} figures")
            continue
        if a.get("pixels") != b.get("pixels"):
            problems.append(f"{scale}: {a.get('pixels')} pixels recorded, {b.get('pixels')} recomputed")
            continue
        for name in ("miou", *(f"per_class_iou.{c}" for c in CLASS_NAMES)):
            va = a["miou"] if name == "miou" else a["per_class_iou"].get(name.split(".", 1)[1])
            vb = b["miou"] if name == "miou" else b["per_class_iou"].get(name.split(".", 1)[1])
            if (va is None) != (vb is None) or (va is not None and abs(va - vb) > iou_tol):
                problems.append(f"{scale}.{name}: recorded {va}, recomputed {vb}")
        ca, cb = np.asarray(a["confusion"], np.int64), np.asarray(b["confusion"], np.int64)
        if ca.shape != cb.shape:
            problems.append(f"{scale}.confusion: shapes differ {ca.shape} vs {cb.shape}")
        else:
            diff = int(np.abs(ca - cb).sum())
            if diff > confusion_tol * max(1, int(ca.sum())):
                problems.append(f"{scale}.confusion: differs by {diff} pixel counts (tolerance "
                                f"{confusion_tol:g} of {int(ca.sum())})")
    return problems
