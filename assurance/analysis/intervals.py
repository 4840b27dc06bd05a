"""Uncertainty of the harness's figures: exact Clopper-Pearson bounds and percentile bootstrap intervals.

Seeded and float64 throughout (docs/architecture.md section 4.4); ``assurance.analysis.metrics`` builds the
results table's intervals from these, ``assurance.analysis.scores`` the separation AUROC's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.stats import beta as _beta


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

    The largest rate ``p`` still compatible, at level ``conf``, with ``k`` events in ``n`` trials:
    ``Beta.ppf(conf, k + 1, n - k)``; 1 when ``k == n``, NaN when ``n == 0`` (no data).
    With 0 unsafe landings in 70 images the bound is 4.19%: that is what such a sample can show.

    >>> round(clopper_pearson_upper(0, 70), 4)
    0.0419
    """
    _check_binomial(k, n, conf)
    if n == 0:
        return math.nan
    if k == n:
        return 1.0
    return float(_beta.ppf(conf, k + 1, n - k))


def clopper_pearson_interval(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Two-sided exact (Clopper-Pearson) interval of a binomial proportion, ``(lo, hi)``.

    Each tail holds ``(1 - conf) / 2``; ``lo`` is 0 when ``k == 0``, ``hi`` is 1 when ``k == n``;
    ``(nan, nan)`` when ``n == 0``.
    """
    _check_binomial(k, n, conf)
    if n == 0:
        return math.nan, math.nan
    alpha = (1.0 - conf) / 2.0
    lo = 0.0 if k == 0 else float(_beta.ppf(alpha, k, n - k + 1))
    hi = 1.0 if k == n else float(_beta.ppf(1.0 - alpha, k + 1, n - k))
    return lo, hi


def _rng(seed: int | np.random.Generator) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def resample_indices(n: int, n_boot: int, seed: int | np.random.Generator) -> np.ndarray:
    """``(n_boot, n)`` image indices drawn with replacement (the same for the same seed)."""
    if isinstance(n_boot, bool) or not isinstance(n_boot, int | np.integer) or n_boot < 1:
        raise ValueError(f"n_boot must be a positive integer, got {n_boot!r}")
    return _rng(seed).integers(0, n, size=(int(n_boot), n))


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


def _apply_stat(stat: Callable[..., Any], samples: np.ndarray) -> np.ndarray:
    try:
        out = np.asarray(stat(samples, axis=1), dtype=np.float64)
        if out.shape == (samples.shape[0],):
            return out
    except TypeError:
        pass
    return np.array([stat(row) for row in samples], dtype=np.float64)


def bootstrap_ci(
    values: Any,
    stat: Callable[..., Any] = np.mean,
    *,
    n_boot: int = 2000,
    conf: float = 0.95,
    seed: int | np.random.Generator = 0,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``stat`` over per-image values, ``(lo, hi)``.

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
        Two-sided confidence level (0.95 -> 2.5th and 97.5th percentiles).
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
    if x.size == 0:
        percentile_interval(np.empty(0), conf)  # validates conf
        return math.nan, math.nan
    idx = resample_indices(x.size, n_boot, seed)
    return percentile_interval(_apply_stat(stat, x[idx]), conf)
