"""The statistics the libraries now compute, against the in-house code they replaced (kept here as the reference):
Clopper-Pearson (``scipy.stats.binomtest``: the same bounds to 1e-8 relative), AUROC and ROC (scikit-learn: the
same numbers), the bootstrap (``scipy.stats.bootstrap``: the same resampled images as before; BCa moves the
interval's ends by a fraction of its width, and where BCa is undefined the interval is the old percentile one,
exactly)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import beta, rankdata

from assurance.analysis.confusion import metric_arrays
from assurance.analysis.intervals import BOOTSTRAP_METHOD, bootstrap_ci, image_bootstrap
from assurance.analysis.metrics import bootstrap_pooled_ci, clopper_pearson_interval, clopper_pearson_upper
from assurance.analysis.scores import auroc, roc_curve


# ---- the replaced implementations, verbatim in substance -------------------------------------------------------
def old_upper(k, n, conf):
    return 1.0 if k == n else float(beta.ppf(conf, k + 1, n - k))


def old_interval(k, n, conf):
    a = (1 - conf) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    return lo, (1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k)))


def old_percentile(values_of_idx, n, n_boot, seed, conf=0.95):
    idx = np.random.default_rng(seed).integers(0, n, size=(n_boot, n))
    reps = values_of_idx(idx)
    reps = reps[np.isfinite(reps)]
    lo, hi = np.percentile(reps, [50 * (1 - conf), 50 * (1 + conf)])
    return float(lo), float(hi)


def old_auroc(s, y):
    s, y = np.asarray(s, float), np.asarray(y, bool)
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    ranks = rankdata(s)
    return float((ranks[y].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def old_roc(s, y):
    s, y = np.asarray(s, float), np.asarray(y, bool)
    finite = s[np.isfinite(s)]
    t = np.concatenate([[np.inf], np.unique(finite)[::-1], [finite.min() - 1.0]])
    n_pos, n_neg = max(int(y.sum()), 1), max(int((~y).sum()), 1)
    return (np.array([(s[~y] > x).sum() / n_neg for x in t]), np.array([(s[y] > x).sum() / n_pos for x in t]), t)


# ---- Clopper-Pearson --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1, 10, 70, 420])
@pytest.mark.parametrize("conf", [0.8, 0.95, 0.99])
def test_clopper_pearson_from_scipy_equals_the_old_beta_inversion(n, conf):
    for k in sorted({0, 1, n // 7, n // 2, n - 1, n}):
        assert clopper_pearson_upper(k, n, conf) == pytest.approx(old_upper(k, n, conf), rel=1e-8, abs=1e-12)
        assert clopper_pearson_interval(k, n, conf) == pytest.approx(old_interval(k, n, conf), rel=1e-8, abs=1e-12)
    assert round(clopper_pearson_upper(0, 70, 0.95), 4) == 0.0419


# ---- AUROC and ROC ----------------------------------------------------------------------------------------------
def test_auroc_and_roc_from_scikit_learn_equal_the_old_code():
    rng = np.random.default_rng(0)
    for trial in range(30):
        n = int(rng.integers(5, 300))
        s = rng.integers(0, 8, n).astype(float) if trial % 2 else rng.normal(size=n)  # ties on odd trials
        y = rng.random(n) < 0.3
        y[0], y[1] = True, False
        assert auroc(s, y) == pytest.approx(old_auroc(s, y), abs=1e-12)
        for ours, old in zip(roc_curve(s, y), old_roc(s, y), strict=True):
            np.testing.assert_allclose(ours, old, rtol=0, atol=1e-12)
    s = np.array([0.1, np.inf, 0.3, -np.inf, 0.2])  # infinite scores keep their order
    y = np.array([False, True, True, False, False])
    assert auroc(s, y) == pytest.approx(old_auroc(s, y))
    for ours, old in zip(roc_curve(s, y), old_roc(s, y), strict=True):
        np.testing.assert_allclose(ours, old)


# ---- the bootstrap ----------------------------------------------------------------------------------------------
def test_the_bootstrap_is_bca_on_the_old_resamples_and_moves_the_ends_by_a_fraction_of_the_width():
    assert BOOTSTRAP_METHOD == "BCa"
    rng = np.random.default_rng(1)
    for _ in range(10):
        gains = rng.choice([-1.0, 0.0, 0.0, 0.0, 0.4, 1.0], size=70)  # skewed, discrete: like per-image gains
        new = bootstrap_ci(gains, seed=0)
        old = old_percentile(lambda idx, g=gains: g[idx].mean(axis=1), 70, 2000, 0)
        width = old[1] - old[0]
        assert new[0] <= gains.mean() <= new[1]
        assert abs(new[0] - old[0]) < 0.25 * width and abs(new[1] - old[1]) < 0.25 * width


def test_where_bca_is_undefined_the_interval_is_the_old_percentile_one_exactly():
    counts = np.zeros((70, 4), np.int64)
    counts[:, 2] = 3  # only accepted safe candidates ...
    counts[:5, 0] = 1  # ... and five images with one rejected unsafe: precision 1 or undefined per resample
    new = bootstrap_pooled_ci(counts, "recall", seed=0)
    old = old_percentile(lambda idx: metric_arrays(counts[idx].sum(axis=1))["recall"], 70, 2000, 0)
    assert new == old == (1.0, 1.0)
    assert bootstrap_ci(np.full(70, 0.25), seed=0) == (0.25, 0.25)  # every resample the same


def test_the_bootstrap_is_deterministic_and_shares_the_resampled_images_across_figures():
    x = np.random.default_rng(2).normal(size=70)
    assert bootstrap_ci(x, seed=3) == bootstrap_ci(x, seed=3)
    seen = []

    def spy(idx):
        seen.append(idx.copy())
        return x[idx].mean(axis=-1)

    image_bootstrap(70, spy, n_boot=50, seed=4)
    image_bootstrap(70, spy, n_boot=50, seed=4)
    assert np.array_equal(seen[0], seen[len(seen) // 2]) and not math.isnan(float(seen[0].sum()))
