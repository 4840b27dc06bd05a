"""Segmentation figures: confusion matrices, per-class IoU and mIoU at both scales.

The protocol is data (recorded in the model card) so that ``uav-el model-card --verify`` can redo
exactly the same computation: every validation frame at the working resolution, and a seeded set of
full-resolution square patches per frame in the reachable rows (:func:`el.segmentation.data.patch_positions`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from el.labels import CLASS_NAMES, NUM_CLASSES
from el.segmentation.data import Prepared, PrepParams
from el.segmentation.pooling import check_pooling


@dataclass(frozen=True, kw_only=True)
class EvalProtocol:
    """Which figures the model card holds: working width, HD patches per frame, their side and seed.

    ``frame_flip``: frames are segmented as the mean softmax of the frame and its mirror image (see
    :class:`~el.segmentation.inference.Segmenter`). It is part of how the network is deployed:
    :meth:`Segmenter.load` follows the card's protocol, so the figures describe the flight code.

    ``frame_scales``: the frame at the working resolution is fed to the network resized by each of
    these factors (1.25: 1280x720 for 1024x576) and the softmax, brought back to the working
    resolution, averaged over them. Only the working-resolution image is used: an upsampled input
    gives the network's stride-4 logits a finer grid, which small objects (people, cars) need.

    ``frame_pooling``: how such a softmax comes back to the working resolution: ``area`` (mean over
    each working pixel's footprint) or ``conservative`` (no forbidden class that a source pixel shows
    is lost; :mod:`el.segmentation.pooling`).
    """

    working_width: int = 1024
    hd_patches: int = 2
    hd_patch_size: int = 384
    seed: int = 12345
    frame_flip: bool = False
    frame_scales: tuple[float, ...] = (1.0,)
    frame_pooling: str = "area"

    def __post_init__(self) -> None:
        if self.working_width < 16 or self.hd_patches < 0 or self.hd_patch_size < 16:
            raise ValueError(f"invalid evaluation protocol: {self}")
        if not isinstance(self.frame_flip, bool):
            raise ValueError(f"frame_flip must be true or false, got {self.frame_flip!r}")
        object.__setattr__(self, "frame_scales", check_frame_scales(self.frame_scales))
        check_pooling(self.frame_pooling)

    def prep_params(self) -> PrepParams:
        return PrepParams(working_width=self.working_width, regions=self.hd_patches,
                          region_size=self.hd_patch_size, seed=self.seed)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), **self.frame_options()}

    def frame_options(self) -> dict[str, Any]:
        """How frames are segmented, as :class:`~el.segmentation.inference.Segmenter` keywords (JSON-ready)."""
        return {"frame_flip": self.frame_flip, "frame_scales": list(self.frame_scales),
                "frame_pooling": self.frame_pooling}

    def segmenter(self, model: Any, **kwargs: Any) -> Any:
        """A :class:`~el.segmentation.inference.Segmenter` that segments frames as this protocol says."""
        from el.segmentation.inference import Segmenter

        return Segmenter(model, working_width=self.working_width, **self.frame_options(), **kwargs)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvalProtocol:
        """From a card's ``evaluation.protocol`` (what an older card lacks takes its default)."""
        out: dict[str, Any] = {}
        for k, v in data.items():
            if k in FRAME_OPTIONS:  # checked in __post_init__
                out[k] = v
            elif k in cls.__dataclass_fields__:
                out[k] = int(v)
        return cls(**out)


MAX_FRAME_SCALE = 2.0
FRAME_OPTIONS = ("frame_flip", "frame_scales", "frame_pooling")  # the protocol's keys that deployment follows too


def check_frame_scales(scales: Any) -> tuple[float, ...]:
    """``frame_scales`` as a tuple of floats; ValueError unless a list of 1 to 4 distinct numbers in [1, 2].

    Factors are upsamplings (the frame is already at the working resolution; a smaller view would
    only lose detail), so the input is enlarged bilinearly and the softmax brought down by area.
    """
    numbers = isinstance(scales, list | tuple) and all(
        isinstance(s, int | float) and not isinstance(s, bool) for s in scales)
    out = tuple(float(s) for s in scales) if numbers else ()
    if not 1 <= len(out) <= 4 or len(set(out)) != len(out) or not all(1.0 <= s <= MAX_FRAME_SCALE for s in out):
        raise ValueError(f"frame_scales must be a list of 1 to 4 distinct factors in [1, {MAX_FRAME_SCALE:g}], "
                         f"got {scales!r}")
    return out


def card_protocol(card: dict[str, Any]) -> EvalProtocol:
    """The evaluation protocol a model card records (defaults for what an older card lacks).

    It is also how the network is deployed: :meth:`Segmenter.load` segments frames as it says.
    """
    return EvalProtocol.from_dict((card.get("evaluation") or {}).get("protocol") or {})


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
