"""Evaluation metrics: monitor classification figures, safety gains, and their uncertainty.

docs/architecture.md sections 4.4-4.5. Metrics live apart from the monitors (pytorch-ood's pattern): the campaign
feeds per-image readouts to a ``ScenarioMetrics`` accumulator and reads one dict with fixed
keys (``RESULT_COLUMNS``, the CSV columns of the results table).
The confusion counts, pooled ratios and their bootstrap live in ``assurance.analysis.confusion``
(re-exported here).

Conventions
-----------
- The positive class is "unsafe candidate" (true hazard 1: a forbidden pixel in its safe disc).
  TP = rejected unsafe, FP = rejected safe, TN = accepted safe, FN = accepted unsafe.
- Precision, recall, FP rate, F1 and MCC are pooled over all candidates of a scenario (the
  published table fits pooled counts). A ratio whose denominator is 0 is NaN, never 0:
  precision with no rejection, recall with no unsafe candidate, FP rate with no safe one,
  F1 with neither a positive nor a rejection (``2TP / (2TP + FP + FN)``), MCC when any
  margin of the confusion matrix is empty (scikit-learn returns 0 there instead).
- Safety gains are hazard reductions, positive = safer: ``g_cm = H(c0) - H(c~)``,
  ``g_rm = H(c~) - H(c*)``, ``g_star = g_cm + g_rm`` (c0 the default action, c~ the core
  model's top-ranked candidate, c* the pipeline's decision; H the true hazard).
- Intervals: BCa bootstrap over images (``intervals.image_bootstrap``: ``scipy.stats.bootstrap``, seeded,
  2000 resamples by default; every figure of a scenario is computed on the same resampled images, so the
  intervals are coherent), except the unsafe-landing rate, which is a binomial proportion and gets exact
  Clopper-Pearson bounds (a bootstrap of 0 events out of 70 would claim [0, 0]).
- Everything is float64 and deterministic for a seed.

Examples
--------
>>> c = confusion([True, True, False, False], [True, False, True, False])
>>> c
Counts(tp=1, fp=1, tn=1, fn=1)
>>> monitor_metrics(c)["precision"]
0.5
>>> round(clopper_pearson_upper(0, 70), 4)
0.0419
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from assurance.analysis.confusion import (
    COUNT_FIELDS,
    METRIC_NAMES,
    Counts,
    bool_vector,
    bootstrap_pooled_ci,
    confusion,
    metric_arrays,
    monitor_metrics,
)
from assurance.analysis.intervals import (
    bootstrap_ci,
    check_boot,
    clopper_pearson_interval,
    clopper_pearson_upper,
    image_bootstrap,
)

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "CI_METRICS",
    "COUNT_FIELDS",
    "METRIC_NAMES",
    "RESULT_COLUMNS",
    "Counts",
    "ImageReadout",
    "SafetyGains",
    "ScenarioMetrics",
    "bootstrap_ci",
    "bootstrap_pooled_ci",
    "clopper_pearson_interval",
    "clopper_pearson_upper",
    "confusion",
    "monitor_metrics",
    "rows_to_frame",
    "safety_gains",
]

CI_METRICS: tuple[str, ...] = (
    "g_cm",
    "mcc",
    "f1",
    "precision",
    "recall",
    "fp_rate",
    "g_rm",
    "overhead_s",
    "g_star",
    "unsafe_landing_rate",
)
"""The figures of the results table that carry a 95% interval (``<name>_lo95`` / ``<name>_hi95``)."""

RESULT_COLUMNS: tuple[str, ...] = (
    "perturbation",
    "severity",
    "monitor",
    "images",
    "candidates",
    *CI_METRICS,  # the figures, in the paper's Table I order
    "unsafe_landing_ub95",
) + tuple(f"{name}_{side}95" for name in CI_METRICS for side in ("lo", "hi"))
"""The CSV columns of the results table (docs/architecture.md section 4.5), the keys of ``ScenarioMetrics.compute``."""


# --------------------------------------------------------------------------------------------
# Safety gains
# --------------------------------------------------------------------------------------------


class SafetyGains(NamedTuple):
    """Per-image safety gains (hazard reductions, positive = safer), float64."""

    g_cm: np.ndarray  # H(c0) - H(c~): what the core model adds over the default action
    g_rm: np.ndarray  # H(c~) - H(c*): what the runtime monitor adds over the core model
    g_star: np.ndarray  # g_cm + g_rm = H(c0) - H(c*): the whole architecture


def safety_gains(h_default: Any, h_top: Any, h_decision: Any) -> SafetyGains:
    """Safety gains from true hazards (scalars or arrays of one value per image).

    Parameters
    ----------
    h_default : float or array-like
        True hazard of the default action's area ``c0``.
    h_top : float or array-like
        True hazard of the core model's top-ranked candidate ``c~`` (pass ``h_default`` for an
        image where the core model found no candidate: it then falls back to ``c0``).
    h_decision : float or array-like
        True hazard of the pipeline's decision ``c*`` (a candidate or the default area).

    Returns
    -------
    SafetyGains
        ``g_star`` is computed as ``g_cm + g_rm``, so the gains add up exactly.
    """
    h0 = np.asarray(h_default, dtype=np.float64)
    ht = np.asarray(h_top, dtype=np.float64)
    hd = np.asarray(h_decision, dtype=np.float64)
    g_cm = h0 - ht
    g_rm = ht - hd
    return SafetyGains(g_cm, g_rm, g_cm + g_rm)


# --------------------------------------------------------------------------------------------
# The scenario accumulator
# --------------------------------------------------------------------------------------------


def _hazard(value: Any, name: str) -> float:
    try:
        h = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}") from None
    if not (math.isfinite(h) and 0.0 <= h <= 1.0):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}")
    return h


@dataclass(frozen=True, kw_only=True, eq=False)
class ImageReadout:
    """The readouts of one image of a scenario that the metrics need (evaluation mode).

    In evaluation mode every candidate gets a monitor decision, even past the one the decision
    loop would have landed on.

    Parameters
    ----------
    unsafe : array-like of shape (n_candidates,), bool
        Per candidate: truly unsafe (true hazard 1, a forbidden ground-truth pixel in its disc).
    rejected : array-like of shape (n_candidates,), bool
        Per candidate: the monitor rejected it.
    h_default : float in [0, 1]
        True hazard of the default action's area ``c0``.
    h_top : float in [0, 1] or None
        True hazard of the core model's top-ranked candidate ``c~``; None when the core model
        found no candidate (``c~`` is then the default action; ``unsafe`` must be empty).
    h_decision : float in [0, 1]
        True hazard of the pipeline's decision ``c*`` (the landing candidate, or the default area).
    overhead_s : float >= 0
        Monitoring time (s) the decision loop spends on this image for this configuration alone.
    decision_unsafe : bool or None
        Whether the decision is an unsafe landing; None (default) means ``h_decision == 1``.
    image_id : str
        Identifies the image; ``ScenarioMetrics`` orders images by it, so the bootstrap does not
        depend on the order in which parallel workers report. Empty = keep insertion order.
    """

    unsafe: np.ndarray
    rejected: np.ndarray
    h_default: float
    h_top: float | None
    h_decision: float
    overhead_s: float = 0.0
    decision_unsafe: bool | None = None
    image_id: str = ""
    counts: Counts = field(init=False, repr=False)

    def __post_init__(self) -> None:
        unsafe = bool_vector(self.unsafe, "unsafe")  # private copies, read-only: counts stay true
        rejected = bool_vector(self.rejected, "rejected")
        unsafe.flags.writeable = False
        rejected.flags.writeable = False
        object.__setattr__(self, "unsafe", unsafe)
        object.__setattr__(self, "rejected", rejected)
        object.__setattr__(self, "counts", confusion(unsafe, rejected))
        object.__setattr__(self, "h_default", _hazard(self.h_default, "h_default"))
        object.__setattr__(self, "h_decision", _hazard(self.h_decision, "h_decision"))
        if self.h_top is None:
            if unsafe.size:
                raise ValueError("h_top is None (no candidate) but candidates were given")
        else:
            object.__setattr__(self, "h_top", _hazard(self.h_top, "h_top"))
            if unsafe.size == 0:
                raise ValueError("h_top is given but there is no candidate; pass h_top=None")
        try:
            overhead = float(self.overhead_s)
        except (TypeError, ValueError):
            overhead = math.nan
        if not (math.isfinite(overhead) and overhead >= 0):
            raise ValueError(f"overhead_s must be a finite number >= 0, got {self.overhead_s!r}")
        object.__setattr__(self, "overhead_s", overhead)
        if self.decision_unsafe is None:
            object.__setattr__(self, "decision_unsafe", self.h_decision >= 1.0)
        else:
            object.__setattr__(self, "decision_unsafe", bool(self.decision_unsafe))
        if not isinstance(self.image_id, str):
            raise ValueError(f"image_id must be a string, got {self.image_id!r}")

    @property
    def h_core(self) -> float:
        """True hazard of the core model's choice ``c~`` (the default area when it had no candidate)."""
        return self.h_default if self.h_top is None else float(self.h_top)


class ScenarioMetrics:
    """Accumulates the readouts of one scenario (perturbation x severity x monitor) into one row.

    Parameters
    ----------
    perturbation : str
        Perturbation name (``assurance.perturbations``).
    severity : int or None
        Its severity (copied to the row as given).
    monitor : str
        Monitor spec, e.g. ``"lhd+ch:tau=0.25"``.
    n_boot : int
        Bootstrap resamples for the intervals.
    seed : int
        Bootstrap seed (the same seed and images give the same intervals).

    Examples
    --------
    >>> sm = ScenarioMetrics(perturbation="fog", severity=3, monitor="lhd")
    >>> sm.update(ImageReadout(unsafe=[True, False], rejected=[True, False], h_default=1.0,
    ...                        h_top=1.0, h_decision=0.2, overhead_s=0.5, image_id="000001"))
    >>> row = sm.compute()
    >>> tuple(row) == RESULT_COLUMNS, row["g_cm"], row["g_rm"], row["g_star"], row["recall"]
    (True, 0.0, 0.8, 0.8, 1.0)
    """

    CONF = 0.95  # the columns are named *_lo95 / *_hi95 / *_ub95

    def __init__(
        self, perturbation: str, severity: int | None, monitor: str, *, n_boot: int = 2000, seed: int = 0
    ) -> None:
        if not isinstance(perturbation, str) or not perturbation:
            raise ValueError(f"perturbation must be a non-empty string, got {perturbation!r}")
        if not isinstance(monitor, str) or not monitor:
            raise ValueError(f"monitor must be a non-empty string, got {monitor!r}")
        if severity is not None and (
            isinstance(severity, bool) or not isinstance(severity, int | np.integer)
        ):
            raise ValueError(f"severity must be an integer or None, got {severity!r}")
        check_boot(n_boot)
        self.perturbation = perturbation
        self.severity = None if severity is None else int(severity)
        self.monitor = monitor
        self.n_boot = int(n_boot)
        self.seed = seed
        self._records: list[ImageReadout] = []
        self._ids: set[str] = set()

    def __len__(self) -> int:
        return len(self._records)

    def update(self, record: ImageReadout) -> None:
        """Add one image's readouts. A non-empty ``image_id`` may be added only once."""
        if not isinstance(record, ImageReadout):
            raise TypeError(f"record must be an ImageReadout, got {type(record).__name__}")
        if record.image_id:
            if record.image_id in self._ids:
                raise ValueError(f"image {record.image_id!r} was already added to this scenario")
            self._ids.add(record.image_id)
        self._records.append(record)

    def extend(self, records: Iterable[ImageReadout]) -> None:
        """``update`` with each record in turn."""
        for record in records:
            self.update(record)

    def compute(self) -> dict[str, Any]:
        """The results row: keys ``RESULT_COLUMNS`` in that order, numbers as Python floats/ints.

        Point values: pooled monitor metrics over all candidates, mean gains and overhead per
        image, unsafe-landing rate with its one-sided exact 95% upper bound (``_ub95``). Intervals:
        BCa bootstrap over images for every figure but the unsafe-landing rate, which
        gets the two-sided exact Clopper-Pearson interval. NaN where undefined (no images, a
        ratio with an empty denominator).
        """
        records = sorted(self._records, key=lambda r: r.image_id)  # stable: ties keep insertion order
        n = len(records)
        row: dict[str, Any] = dict.fromkeys(RESULT_COLUMNS, math.nan)
        row.update(perturbation=self.perturbation, severity=self.severity, monitor=self.monitor)
        row["images"] = n
        row["candidates"] = sum(r.counts.total for r in records)
        if n == 0:
            return row

        counts = np.array([r.counts.as_array() for r in records], dtype=np.int64).reshape(n, 4)
        gains = safety_gains(
            [r.h_default for r in records], [r.h_core for r in records], [r.h_decision for r in records]
        )
        per_image = {
            "g_cm": gains.g_cm,
            "g_rm": gains.g_rm,
            "g_star": gains.g_star,
            "overhead_s": np.array([r.overhead_s for r in records], dtype=np.float64),
        }
        pooled = metric_arrays(counts.sum(axis=0))

        def ci(statistic: Any) -> tuple[float, float]:  # the same resampled images for every figure (seed)
            return image_bootstrap(n, statistic, n_boot=self.n_boot, conf=self.CONF, seed=self.seed)

        for name in METRIC_NAMES:
            point = float(pooled[name])
            row[name] = point
            if math.isfinite(point):
                row[f"{name}_lo95"], row[f"{name}_hi95"] = ci(
                    lambda idx, name=name: metric_arrays(counts[idx].sum(axis=-2))[name])
        for name, values in per_image.items():
            row[name] = float(values.mean())
            row[f"{name}_lo95"], row[f"{name}_hi95"] = ci(lambda idx, values=values: values[idx].mean(axis=-1))

        k = sum(bool(r.decision_unsafe) for r in records)
        row["unsafe_landing_rate"] = k / n
        row["unsafe_landing_ub95"] = clopper_pearson_upper(k, n, self.CONF)
        row["unsafe_landing_rate_lo95"], row["unsafe_landing_rate_hi95"] = clopper_pearson_interval(
            k, n, self.CONF
        )
        return row


def rows_to_frame(rows: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """A DataFrame of result rows (``ScenarioMetrics.compute``), columns in ``RESULT_COLUMNS`` order."""
    import pandas as pd

    return pd.DataFrame(list(rows), columns=list(RESULT_COLUMNS))
