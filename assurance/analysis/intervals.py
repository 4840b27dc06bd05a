"""Uncertainty of the harness's figures: exact Clopper-Pearson bounds (``scipy.stats.binomtest``), the decision of
a rate bound from them at any sample size (``decide_rate_bound``), and one bootstrap over images
(``scipy.stats.bootstrap``, BCa).

Seeded and float64 throughout (docs/architecture.md section 4.4); ``assurance.analysis.metrics`` builds the
results table's intervals from these, ``assurance.analysis.scores`` the separation AUROC's.

The bootstrap is BCa (bias-corrected and accelerated): at the campaign's n = 70 images the per-image gains are
bounded and skewed (most images gain 0, a few +-1) and the pooled ratios are ratio estimators, for which the
percentile interval is biased and under-covers; BCa corrects both with a jackknife of only n evaluations.
Where BCa is undefined (every resample gives the same value, or the statistic is undefined in some resamples or
jackknife samples, e.g. a precision with no rejection), the interval is the percentile interval of the same
resamples, undefined resamples left out.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

BOOTSTRAP_METHOD = "BCa"
"""The interval method of ``image_bootstrap`` (the percentile interval where BCa is undefined)."""


def _check_binomial(k: int, n: int, conf: float) -> None:
    for name, value in (("k", k), ("n", n)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    if k > n:
        raise ValueError(f"k must not exceed n, got k={k}, n={n}")
    if not 0 < conf < 1:
        raise ValueError(f"conf must lie in (0, 1), got {conf!r}")


def clopper_pearson_upper(k: int, n: int, conf: float = 0.95) -> float:
    """One-sided exact (Clopper-Pearson) upper confidence bound of a binomial proportion.

    The largest rate ``p`` still compatible, at level ``conf``, with ``k`` events in ``n`` trials
    (``scipy.stats.binomtest(k, n, alternative="less").proportion_ci(conf, method="exact").high``); 1 when
    ``k == n``, NaN when ``n == 0`` (no data). With 0 unsafe landings in 70 images the bound is 4.19%: that is
    what such a sample can show.

    >>> round(clopper_pearson_upper(0, 70), 4)
    0.0419
    """
    _check_binomial(k, n, conf)
    if n == 0:
        return math.nan
    ci = stats.binomtest(int(k), int(n), alternative="less").proportion_ci(confidence_level=conf, method="exact")
    return float(ci.high)


def clopper_pearson_interval(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Two-sided exact (Clopper-Pearson) interval of a binomial proportion, ``(lo, hi)``
    (``scipy.stats.binomtest(k, n).proportion_ci(conf, method="exact")``).

    Each tail holds ``(1 - conf) / 2``; ``lo`` is 0 when ``k == 0``, ``hi`` is 1 when ``k == n``;
    ``(nan, nan)`` when ``n == 0``.
    """
    _check_binomial(k, n, conf)
    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(int(k), int(n)).proportion_ci(confidence_level=conf, method="exact")
    return float(ci.low), float(ci.high)


def clopper_pearson_lower(k: int, n: int, conf: float = 0.95) -> float:
    """One-sided exact (Clopper-Pearson) lower confidence bound of a binomial proportion.

    The smallest rate still compatible, at level ``conf``, with ``k`` events in ``n`` trials
    (``scipy.stats.binomtest(k, n, alternative="greater")``): above a target, the sample already shows the
    target missed, however small it is. 0 when ``k == 0``, NaN when ``n == 0``.

    >>> round(clopper_pearson_lower(7, 12), 4)
    0.3152
    """
    _check_binomial(k, n, conf)
    if n == 0:
        return math.nan
    if k == 0:
        return 0.0
    ci = stats.binomtest(int(k), int(n), alternative="greater").proportion_ci(confidence_level=conf, method="exact")
    return float(ci.low)


BOUND_MET, BOUND_MISSED, BOUND_UNDECIDED = "met", "missed", "undecided"
"""The verdicts of ``decide_rate_bound``."""


@dataclass(frozen=True)
class BoundDecision:
    """What ``k`` events in ``n`` trials say of "the rate is at most ``target``" at one-sided ``conf``."""

    k: int
    n: int
    target: float
    conf: float
    lower: float
    upper: float
    verdict: str

    def text(self) -> str:
        """The numbers behind the verdict, e.g. ``7 of 12 (0.583; one-sided 95% lower bound 0.315, upper 0.819)``."""
        if not self.n:
            return "0 of 0 (no data)"
        level = f"{self.conf * 100:.10g}%"
        return (f"{self.k} of {self.n} ({self.k / self.n:.3f}; one-sided {level} lower bound {self.lower:.3f}, "
                f"upper {self.upper:.3f})")


def decide_rate_bound(k: int, n: int, target: float, conf: float = 0.95, *, min_n: int = 1) -> BoundDecision:
    """Decide "the rate is at most ``target``" with ``conf`` from ``k`` of ``n``, at any sample size.

    ``missed`` when the one-sided lower bound exceeds ``target`` (the data already show it broken, whatever
    ``n``); ``met`` when the one-sided upper bound is at most ``target`` and ``n >= min_n`` (the smallest sample a
    requirement accepts as verification); ``undecided`` in between, and without data.

    >>> decide_rate_bound(7, 12, 0.05).verdict, decide_rate_bound(0, 12, 0.05).verdict
    ('missed', 'undecided')
    """
    if not 0 <= target <= 1:
        raise ValueError(f"target must lie in [0, 1], got {target!r}")
    lower, upper = clopper_pearson_lower(k, n, conf), clopper_pearson_upper(k, n, conf)
    if n and lower > target:
        verdict = BOUND_MISSED
    elif n and n >= min_n and upper <= target:
        verdict = BOUND_MET
    else:
        verdict = BOUND_UNDECIDED
    return BoundDecision(int(k), int(n), float(target), float(conf), lower, upper, verdict)


def _rng(seed: int | np.random.Generator) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def check_boot(n_boot: Any, conf: float = 0.95) -> None:
    """ValueError unless ``n_boot`` is a positive integer and ``conf`` lies in (0, 1)."""
    if isinstance(n_boot, bool) or not isinstance(n_boot, int | np.integer) or n_boot < 1:
        raise ValueError(f"n_boot must be a positive integer, got {n_boot!r}")
    if not 0 < conf < 1:
        raise ValueError(f"conf must lie in (0, 1), got {conf!r}")


def percentile_interval(replicates: np.ndarray, conf: float) -> tuple[float, float]:
    """Percentile interval of bootstrap replicates; NaN replicates (an undefined ratio in a
    resample) are left out; ``(nan, nan)`` if none is finite."""
    if not 0 < conf < 1:
        raise ValueError(f"conf must lie in (0, 1), got {conf!r}")
    finite = replicates[np.isfinite(replicates)]
    if finite.size == 0:
        return math.nan, math.nan
    lo, hi = np.percentile(finite, [50.0 * (1.0 - conf), 50.0 * (1.0 + conf)])
    return float(lo), float(hi)


def image_bootstrap(n: int, statistic: Callable[[np.ndarray], Any], *, n_boot: int = 2000, conf: float = 0.95,
                    seed: int | np.random.Generator = 0) -> tuple[float, float]:
    """The one bootstrap of the harness: images resampled with replacement, BCa interval of ``statistic``.

    ``statistic(idx)`` maps image indices ``idx`` of shape ``(..., m)`` (the last axis one sample of images) to
    the figure, shape ``(...)``: a per-image mean, a pooled ratio of the resampled images' counts, an AUROC over
    their candidates. ``scipy.stats.bootstrap`` draws ``n_boot`` resamples from ``seed`` (the same images for
    the same seed and ``n``, whatever the figure) and the jackknife for the BCa acceleration; where BCa is
    undefined the percentile interval of the same resamples is returned (module docstring). ``(nan, nan)``
    without images.
    """
    check_boot(n_boot, conf)
    if n == 0:
        return math.nan, math.nan
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    if n == 1:
        value = float(np.asarray(statistic(np.zeros((1, 1), np.intp)), dtype=np.float64).reshape(-1)[0])
        return (value, value) if math.isfinite(value) else (math.nan, math.nan)

    def stat(idx: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.asarray(statistic(np.moveaxis(idx, axis, -1)), dtype=np.float64)

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")  # scipy's DegenerateDataWarning / nan warnings: handled below
        res = stats.bootstrap((np.arange(n),), stat, n_resamples=int(n_boot), confidence_level=conf,
                              method=BOOTSTRAP_METHOD, vectorized=True, rng=rng)
    lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    if math.isfinite(lo) and math.isfinite(hi):
        return lo, hi
    return percentile_interval(np.asarray(res.bootstrap_distribution, dtype=np.float64), conf)


def _apply_stat(stat: Callable[..., Any], samples: np.ndarray) -> np.ndarray:
    flat = samples.reshape(-1, samples.shape[-1])
    try:
        out = np.asarray(stat(flat, axis=1), dtype=np.float64)
        if out.shape == (flat.shape[0],):
            return out.reshape(samples.shape[:-1])
    except TypeError:
        pass
    return np.array([stat(row) for row in flat], dtype=np.float64).reshape(samples.shape[:-1])


def bootstrap_ci(
    values: Any,
    stat: Callable[..., Any] = np.mean,
    *,
    n_boot: int = 2000,
    conf: float = 0.95,
    seed: int | np.random.Generator = 0,
) -> tuple[float, float]:
    """Bootstrap interval of ``stat`` over per-image values, ``(lo, hi)`` (``image_bootstrap``: BCa).

    Parameters
    ----------
    values : array-like of shape (n_images,)
        One value per image (e.g. a safety gain); images are resampled with replacement.
    stat : callable
        Statistic of a sample; numpy reductions taking ``axis`` are vectorised, any other
        callable ``stat(sample) -> float`` is applied resample by resample.
    n_boot : int
        Number of resamples.
    conf : float
        Two-sided confidence level.
    seed : int or numpy.random.Generator
        The same seed draws the same resampled images (for the same number of images) as
        ``bootstrap_pooled_ci``.

    Returns
    -------
    (float, float)
        ``(nan, nan)`` for an empty sample.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"values must be one-dimensional, got shape {x.shape}")
    return image_bootstrap(x.size, lambda idx: _apply_stat(stat, x[idx]), n_boot=n_boot, conf=conf, seed=seed)
