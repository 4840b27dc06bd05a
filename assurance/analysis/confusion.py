"""Confusion counts of a monitor, its pooled ratio metrics, and their bootstrap over images.

Split from :mod:`assurance.analysis.metrics` (which re-exports every public name here) so that each
module stays small; the conventions (positive class "unsafe candidate", NaN for an empty
denominator, pooled counts) are those documented there.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from assurance.analysis.intervals import check_boot, image_bootstrap

__all__ = [
    "COUNT_FIELDS",
    "METRIC_NAMES",
    "Counts",
    "bool_vector",
    "bootstrap_pooled_ci",
    "confusion",
    "metric_arrays",
    "monitor_metrics",
]

COUNT_FIELDS: tuple[str, ...] = ("tp", "fp", "tn", "fn")
METRIC_NAMES: tuple[str, ...] = ("precision", "recall", "fp_rate", "f1", "mcc")
"""Keys of ``monitor_metrics``, in a fixed order."""


# --------------------------------------------------------------------------------------------
# Confusion counts and the pooled monitor metrics
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Counts:
    """Confusion counts of a monitor; the positive class is "unsafe candidate"."""

    tp: int = 0  # rejected unsafe
    fp: int = 0  # rejected safe
    tn: int = 0  # accepted safe
    fn: int = 0  # accepted unsafe

    def __post_init__(self) -> None:
        for name in COUNT_FIELDS:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
            object.__setattr__(self, name, int(value))

    def __add__(self, other: Counts) -> Counts:
        if not isinstance(other, Counts):
            return NotImplemented
        return Counts(self.tp + other.tp, self.fp + other.fp, self.tn + other.tn, self.fn + other.fn)

    @property
    def total(self) -> int:
        """Number of candidates counted."""
        return self.tp + self.fp + self.tn + self.fn

    def as_array(self) -> np.ndarray:
        """``[tp, fp, tn, fn]`` as an int64 array."""
        return np.array([self.tp, self.fp, self.tn, self.fn], dtype=np.int64)


def bool_vector(values: Any, name: str) -> np.ndarray:
    """``values`` as a 1-D bool array; ValueError unless it is one-dimensional and holds booleans or 0/1."""
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if arr.size and arr.dtype != bool:
        if not np.isin(arr, (0, 1)).all():
            raise ValueError(f"{name} must hold booleans (or 0/1), got dtype {arr.dtype}")
    return arr.astype(bool)


def confusion(unsafe: Any, rejected: Any) -> Counts:
    """Confusion counts of a monitor over candidates.

    Parameters
    ----------
    unsafe : array-like of shape (n,), bool
        True where the candidate is truly unsafe (ground-truth true hazard 1).
    rejected : array-like of shape (n,), bool
        True where the monitor rejected the candidate.

    Returns
    -------
    Counts
    """
    u = bool_vector(unsafe, "unsafe")
    r = bool_vector(rejected, "rejected")
    if u.shape != r.shape:
        raise ValueError(f"unsafe and rejected must have the same length, got {u.size} and {r.size}")
    return Counts(
        tp=int(np.count_nonzero(u & r)),
        fp=int(np.count_nonzero(~u & r)),
        tn=int(np.count_nonzero(~u & ~r)),
        fn=int(np.count_nonzero(u & ~r)),
    )


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    out = np.full(np.broadcast(num, den).shape, np.nan)
    np.divide(num, den, out=out, where=den > 0)
    return out


def metric_arrays(counts: np.ndarray) -> dict[str, np.ndarray]:
    """Pooled metrics of count rows: ``counts[..., :]`` = tp, fp, tn, fn. NaN where undefined."""
    c = np.asarray(counts, dtype=np.float64)
    tp, fp, tn, fn = c[..., 0], c[..., 1], c[..., 2], c[..., 3]
    pred_pos, pos, neg, pred_neg = tp + fp, tp + fn, fp + tn, tn + fn
    den = np.sqrt(pred_pos * pos) * np.sqrt(neg * pred_neg)
    return {
        "precision": _ratio(tp, pred_pos),
        "recall": _ratio(tp, pos),
        "fp_rate": _ratio(fp, neg),
        "f1": _ratio(2 * tp, 2 * tp + fp + fn),
        "mcc": _ratio(tp * tn - fp * fn, den),
    }


def monitor_metrics(counts: Counts) -> dict[str, float]:
    """Precision, recall, FP rate, F1 and MCC of ``counts`` (keys ``METRIC_NAMES``; NaN if undefined)."""
    values = metric_arrays(counts.as_array())
    return {name: float(values[name]) for name in METRIC_NAMES}


# --------------------------------------------------------------------------------------------
# Bootstrap of the pooled ratios (images resampled, counts added up)
# --------------------------------------------------------------------------------------------


def _counts_matrix(per_image_counts: Any) -> np.ndarray:
    rows = list(per_image_counts) if not isinstance(per_image_counts, np.ndarray) else per_image_counts
    if len(rows) and isinstance(rows[0], Counts):
        return np.array([c.as_array() for c in rows], dtype=np.int64).reshape(-1, 4)
    m = np.asarray(rows, dtype=np.int64)
    if m.size == 0:
        return m.reshape(0, 4)
    if m.ndim != 2 or m.shape[1] != 4 or (m < 0).any():
        raise ValueError(
            f"per_image_counts must be Counts or rows of 4 counts (tp, fp, tn, fn), got {m.shape}"
        )
    return m


def bootstrap_pooled_ci(
    per_image_counts: Iterable[Counts] | np.ndarray,
    metric_name: str,
    *,
    n_boot: int = 2000,
    conf: float = 0.95,
    seed: int | np.random.Generator = 0,
) -> tuple[float, float]:
    """Bootstrap interval (``image_bootstrap``: BCa) of a pooled ratio metric, resampling images.

    Each resample draws images with replacement, adds up their confusion counts and
    recomputes the pooled metric, so the interval reflects that candidates of one image are
    not independent. Resamples where the metric is undefined are left out; the interval is
    ``(nan, nan)`` when the metric on the full sample is undefined.

    Parameters
    ----------
    per_image_counts : sequence of Counts, or array of shape (n_images, 4)
        Confusion counts of each image (columns tp, fp, tn, fn).
    metric_name : str
        One of ``METRIC_NAMES``.
    n_boot, conf, seed
        As in ``bootstrap_ci``.
    """
    if metric_name not in METRIC_NAMES:
        raise ValueError(f"unknown metric {metric_name!r}; valid names: {', '.join(METRIC_NAMES)}")
    m = _counts_matrix(per_image_counts)
    check_boot(n_boot, conf)
    if m.shape[0] == 0 or not np.isfinite(metric_arrays(m.sum(axis=0))[metric_name]):
        return math.nan, math.nan
    return image_bootstrap(m.shape[0], lambda idx: metric_arrays(m[idx].sum(axis=-2))[metric_name],
                           n_boot=n_boot, conf=conf, seed=seed)
