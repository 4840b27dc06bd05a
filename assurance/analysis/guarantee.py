"""The calibration's order-statistic threshold (the ``guarantee`` criterion of ``assurance.analysis.criteria``).

Moved here from ``assurance.fitting.calibration`` (which re-exports it) so that the analysis layer's threshold
criteria can use it: the rule and its guarantee are described in that module's docstring.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.stats import binom

from assurance.analysis.metrics import clopper_pearson_upper
from el.monitors.calibration import CalibrationError


def _check_rates(miss_rate: float, confidence: float) -> None:
    for name, v in (("miss rate", miss_rate), ("confidence", confidence)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 < float(v) < 1.0:
            raise CalibrationError(f"{name} must lie in (0, 1), got {v!r}")


def min_unsafe_needed(miss_rate: float, confidence: float) -> int:
    """Fewest unsafe calibration candidates that can certify ``miss_rate`` at ``confidence`` (k = 1)."""
    _check_rates(miss_rate, confidence)
    return int(math.ceil(math.log(1.0 - confidence) / math.log(1.0 - miss_rate)))


def calibrate_threshold(unsafe_scores: Any, miss_rate: float, confidence: float) -> dict[str, Any]:
    """The threshold with the guarantee above, from the scores of the truly unsafe calibration candidates.

    Returns ``{"threshold", "k", "n", "bound", "accepted"}``: ``bound`` is the Clopper-Pearson upper
    bound of the miss rate at ``confidence`` (``<= miss_rate``), ``accepted`` the unsafe calibration
    candidates the threshold accepts.
    """
    _check_rates(miss_rate, confidence)
    s = np.sort(np.asarray(unsafe_scores, dtype=np.float64))
    if s.ndim != 1 or np.isnan(s).any():
        raise CalibrationError("unsafe scores must be a one-dimensional array without NaN")
    n = int(s.size)
    delta = 1.0 - confidence
    # largest k in 1..n with P(Bin(n, miss_rate) <= k - 1) <= delta
    cdf = binom.cdf(np.arange(n), n, miss_rate)  # cdf[j] = P(Bin <= j), j = k - 1
    ok = np.flatnonzero(cdf <= delta)
    if n == 0 or ok.size == 0:
        need = min_unsafe_needed(miss_rate, confidence)
        raise CalibrationError(f"{n} truly unsafe calibration candidate(s): at least {need} are needed to "
                               f"certify a miss rate of {miss_rate:g} at confidence {confidence:g}")
    k = int(ok[-1]) + 1
    threshold = float(np.nextafter(s[k - 1], -np.inf))
    if not math.isfinite(threshold):
        raise CalibrationError(f"the {k}-th smallest unsafe score is {s[k - 1]!r}: no finite threshold below it")
    accepted = int((s <= threshold).sum())
    return {"threshold": threshold, "k": k, "n": n, "accepted": accepted,
            "bound": clopper_pearson_upper(accepted, n, confidence)}
