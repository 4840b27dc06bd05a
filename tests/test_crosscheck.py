"""The project's own statistics and geometry against independent reference implementations.

Clopper-Pearson and the bootstrap are the libraries' own now (``tests/test_stats_libraries.py`` checks them
against the in-house numbers they replaced); here: Clopper-Pearson against its defining tail equations, the
bootstrap against ``scipy.stats.bootstrap(method="BCa")`` called directly, the clearance EDT against
``scipy.ndimage.distance_transform_edt``, and K-means against scikit-learn's ``KMeans`` from the
same initial centres. The formulas are in docs/architecture.md sections 3.3-3.4 and 4.5.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage, stats
from threadpoolctl import threadpool_limits

from assurance.analysis.metrics import bootstrap_ci, clopper_pearson_interval, clopper_pearson_upper
from el.landing.candidates import DIST_CAP, _exact_edt
from el.landing.representatives import _kmeans_pp, kmeans

# (k, n) pairs: the edges (0 and n events), the demo and paper sample sizes, small and large n.
BINOMIAL_CASES = [(0, 1), (1, 1), (0, 10), (3, 10), (10, 10), (0, 70), (1, 70), (14, 70), (69, 70),
                  (70, 70), (5, 420), (161, 420), (0, 1000)]
# scipy finds the exact bounds with a root finder on the binomial tail, the project inverts the Beta
# distribution (Beta.ppf): the two agree to about 1e-10 relative (seen: 6e-10 at (1, 70)), not bit for bit.
SCIPY_ROOT_TOL = {"rel": 1e-8, "abs": 1e-12}


@pytest.mark.parametrize(("k", "n"), BINOMIAL_CASES)
@pytest.mark.parametrize("conf", [0.95, 0.99, 0.8])
def test_clopper_pearson_two_sided_matches_scipy(k: int, n: int, conf: float) -> None:
    ref = stats.binomtest(k, n).proportion_ci(confidence_level=conf, method="exact")
    lo, hi = clopper_pearson_interval(k, n, conf)
    assert lo == pytest.approx(ref.low, **SCIPY_ROOT_TOL)
    assert hi == pytest.approx(ref.high, **SCIPY_ROOT_TOL)
    # and the defining equations, exactly in the tails: P(X >= k | lo) = P(X <= k | hi) = (1 - conf) / 2
    tail = (1 - conf) / 2
    if k > 0:
        assert stats.binom.sf(k - 1, n, lo) == pytest.approx(tail, rel=1e-9)
    if k < n:
        assert stats.binom.cdf(k, n, hi) == pytest.approx(tail, rel=1e-9)


@pytest.mark.parametrize(("k", "n"), BINOMIAL_CASES)
@pytest.mark.parametrize("conf", [0.95, 0.99])
def test_clopper_pearson_one_sided_upper_matches_scipy(k: int, n: int, conf: float) -> None:
    # The one-sided upper bound is scipy's interval with alternative="less" (its low end is 0).
    ref = stats.binomtest(k, n, alternative="less").proportion_ci(confidence_level=conf, method="exact")
    assert ref.low == 0.0
    assert clopper_pearson_upper(k, n, conf) == pytest.approx(ref.high, **SCIPY_ROOT_TOL)


@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (14, 70), (70, 70)])
def test_one_sided_lower_bound_is_the_two_sided_bound_at_twice_the_tail(k: int, n: int) -> None:
    # scipy's one-sided lower bound ("greater") at level c is the two-sided lower end at 2c - 1.
    ref = stats.binomtest(k, n, alternative="greater").proportion_ci(confidence_level=0.95, method="exact")
    assert ref.high == 1.0
    assert clopper_pearson_interval(k, n, 0.90)[0] == pytest.approx(ref.low, **SCIPY_ROOT_TOL)


@pytest.mark.parametrize("seed", [0, 1, 7])
@pytest.mark.parametrize("n", [10, 70])
def test_bootstrap_is_scipys_bca_on_the_same_seed(seed: int, n: int) -> None:
    values = np.random.default_rng(100 + seed).normal(0.3, 0.4, size=n)
    ours = bootstrap_ci(values, np.mean, n_boot=2000, seed=np.random.default_rng(seed))
    ref = stats.bootstrap((values,), np.mean, n_resamples=2000, method="BCa", confidence_level=0.95,
                          vectorized=True, rng=np.random.default_rng(seed))
    # the same resampled images; the statistic sees image indices, so the mean's summation order may differ
    assert ours[0] == pytest.approx(ref.confidence_interval.low, rel=1e-12, abs=1e-15)
    assert ours[1] == pytest.approx(ref.confidence_interval.high, rel=1e-12, abs=1e-15)


def test_bootstrap_of_a_non_vectorised_statistic_matches_scipy() -> None:
    values = np.random.default_rng(3).integers(0, 2, size=40).astype(float)  # e.g. unsafe landings

    def share(sample: np.ndarray) -> float:  # no axis argument: applied resample by resample
        return float(np.count_nonzero(sample) / sample.size)

    ours = bootstrap_ci(values, share, n_boot=500, seed=np.random.default_rng(5))
    ref = stats.bootstrap((values,), share, n_resamples=500, method="BCa", vectorized=False,
                          rng=np.random.default_rng(5))
    assert ours == pytest.approx((ref.confidence_interval.low, ref.confidence_interval.high), rel=1e-12)


def _random_free_mask(rng: np.random.Generator, h: int, w: int, density: float) -> np.ndarray:
    free = np.ones((h, w), dtype=np.uint8)
    free[rng.random((h, w)) < density] = 0
    free[rng.integers(h), :] = 0 if rng.random() < 0.5 else free[0]  # sometimes a whole forbidden row
    if free.all():
        free[h // 2, w // 2] = 0
    return free


@pytest.mark.parametrize(("seed", "h", "w", "density"), [(0, 40, 60, 0.01), (1, 64, 64, 0.1),
                                                        (2, 33, 97, 0.001), (3, 120, 80, 0.3)])
def test_exact_edt_equals_scipy_distance_transform_edt(seed: int, h: int, w: int, density: float) -> None:
    free = _random_free_mask(np.random.default_rng(seed), h, w, density)
    ours = _exact_edt(free)
    ref = np.minimum(ndimage.distance_transform_edt(free), DIST_CAP)
    assert ours.dtype == np.float32
    # The project rounds the squared distance to the integer it must be: its result is the float32
    # square root of the exact squared distance, so equal to scipy's exact EDT in float32.
    np.testing.assert_array_equal(ours, ref.astype(np.float32))


def test_exact_edt_equals_scipy_on_a_working_size_map() -> None:
    free = _random_free_mask(np.random.default_rng(9), 576, 1024, 2e-5)
    np.testing.assert_array_equal(_exact_edt(free), np.minimum(ndimage.distance_transform_edt(free), DIST_CAP)
                                  .astype(np.float32))


def test_exact_edt_is_capped_far_from_any_forbidden_pixel() -> None:
    # 40 rows, not fewer: on maps of 2 to 8 rows OpenCV's precise transform was seen to return 886
    # where the exact distance is sqrt(886^2 + 1) (52 pixels off by < 0.001 px, all beyond 880 px),
    # far from any safety radius and from working maps, which are 1024 x 540..576.
    free = np.ones((40, 1400), dtype=np.uint8)
    free[0, 0] = 0
    ours = _exact_edt(free)
    ref = ndimage.distance_transform_edt(free)
    assert ours[0, -1] == np.float32(DIST_CAP) < ref[0, -1]
    np.testing.assert_array_equal(ours[ref < DIST_CAP], ref[ref < DIST_CAP].astype(np.float32))


def _region_points(rng: np.random.Generator, n: int) -> np.ndarray:
    """Pixel coordinates of an L-shaped region with a dense blob: non-convex, unevenly filled."""
    a = np.column_stack([rng.integers(0, 60, n), rng.integers(0, 12, n)])
    b = np.column_stack([rng.integers(48, 60, n), rng.integers(0, 80, n)])
    blob = np.column_stack([rng.normal(20, 2, n // 2), rng.normal(6, 2, n // 2)])
    return np.vstack([a, b, blob]).astype(np.float64)


def _inertia(points: np.ndarray, centres: np.ndarray) -> float:
    return float(((points[:, None, :] - centres[None]) ** 2).sum(axis=2).min(axis=1).sum())


@pytest.mark.parametrize(("seed", "k"), [(0, 1), (1, 3), (2, 5), (3, 9)])
def test_kmeans_inertia_equals_sklearn_from_the_same_initial_centres(seed: int, k: int) -> None:
    from sklearn.cluster import KMeans

    points = _region_points(np.random.default_rng(seed), 150)
    init = _kmeans_pp(points, k, np.random.default_rng(seed))  # what kmeans(seed=seed) starts from
    ours = kmeans(points, k, seed=seed, n_init=1, max_iter=300, tol=0.0)
    with threadpool_limits(1):  # sklearn's OpenMP pool is slow to start on a busy 2-core machine
        ref = KMeans(n_clusters=k, init=init, n_init=1, max_iter=300, tol=0.0, algorithm="lloyd").fit(points)
    # Lloyd's iterations from the same centres reach the same fixed point; sklearn's inertia_ is
    # computed in float64 over the same points.
    assert _inertia(points, ours) == pytest.approx(ref.inertia_, rel=1e-9)
    np.testing.assert_allclose(np.sort(ours, axis=0), np.sort(ref.cluster_centers_, axis=0), rtol=1e-9, atol=1e-9)


def test_kmeans_best_of_several_inits_is_no_worse_than_sklearn_single_run() -> None:
    from sklearn.cluster import KMeans

    points = _region_points(np.random.default_rng(11), 200)
    ours = kmeans(points, 6, seed=4, n_init=5)
    with threadpool_limits(1):
        ref = KMeans(n_clusters=6, n_init=1, random_state=0, algorithm="lloyd").fit(points)
    # A weak bound on purpose (different seeding streams): 5 restarts should not lose to one by >5%.
    assert _inertia(points, ours) <= 1.05 * ref.inertia_
