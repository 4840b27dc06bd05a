"""The vectorised AUROC of the bootstrap over images (``assurance.analysis.auroc_batch``, issue 52): every resample
equals scikit-learn's ``roc_auc_score`` of it bit for bit (ties, NaN and infinite scores, one-class resamples, long
curves), so the AUROC intervals of ``uav-el table`` are those of the per-resample code it replaced."""

from __future__ import annotations

import math

import numpy as np
import pytest

from assurance.analysis import auroc_batch
from assurance.analysis.auroc_batch import GroupedAuroc, curve_areas
from assurance.analysis.intervals import image_bootstrap
from assurance.analysis.scores import auroc, grouped_auroc_ci


def per_resample(inverse: np.ndarray, scores: np.ndarray, unsafe: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The statistic before issue 52: ``scores.auroc`` (scikit-learn) of each resample's candidates in turn."""
    members = [np.flatnonzero(inverse == g) for g in range(int(inverse.max()) + 1)]
    flat = idx.reshape(-1, idx.shape[-1])
    out = [auroc(scores[rows], unsafe[rows]) for rows in (np.concatenate([members[g] for g in r]) for r in flat)]
    return np.array(out).reshape(idx.shape[:-1])


def candidates(rng: np.random.Generator, kind: str, n_groups: int, most: int = 12) -> tuple[np.ndarray, ...]:
    inverse = np.repeat(np.arange(n_groups), rng.integers(1, most, n_groups))  # every group holds a candidate
    n = len(inverse)
    if kind == "continuous":
        s = rng.random(n)
    elif kind == "ties":
        s = rng.integers(0, 4, n).astype(float)
    else:  # NaN and infinite scores among rounded ones
        s = np.round(rng.normal(size=n), 1)
        s[rng.random(n) < 0.1], s[rng.random(n) < 0.05], s[rng.random(n) < 0.05] = np.nan, np.inf, -np.inf
    return inverse, s, rng.random(n) < rng.uniform(0.05, 0.6)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal bit for bit, NaN where the other is NaN."""
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


@pytest.mark.parametrize("kind", ["continuous", "ties", "nan_inf"])
def test_every_resample_equals_scikit_learn_bit_for_bit(kind):
    rng = np.random.default_rng(["continuous", "ties", "nan_inf"].index(kind))
    for _ in range(15):
        n_groups = int(rng.integers(2, 12))
        inverse, s, y = candidates(rng, kind, n_groups)
        idx = rng.integers(0, n_groups, (25, n_groups))
        assert same(GroupedAuroc(inverse, n_groups, s, y)(idx), per_resample(inverse, s, y, idx))


def test_long_curves_equal_scikit_learn_too():
    """Past 128 trapezoids numpy adds up pairwise in blocks: each row is summed as scikit-learn sums it."""
    rng = np.random.default_rng(7)
    inverse, s, y = candidates(rng, "continuous", 30, most=40)
    idx = rng.integers(0, 30, (12, 30))
    areas = GroupedAuroc(inverse, 30, s, y)(idx)
    assert len(s) > 300 and np.isfinite(areas).all()
    assert same(areas, per_resample(inverse, s, y, idx))


def test_undefined_and_degenerate_samples_are_nan_or_one_half_as_before():
    s = np.array([0.2, 0.7, 0.7, np.nan, 0.1])
    y = np.array([False, True, False, True, True])
    stat = GroupedAuroc(np.array([0, 1, 1, 2, 3]), 4, s, y)
    # group 0 alone: no positive; group 2 alone: its only candidate has no score; groups 1 and 1: a tie
    out = stat(np.array([[0, 0], [2, 2], [1, 1], [0, 3]]))
    assert np.isnan(out[0]) and np.isnan(out[1]) and out[2] == 0.5 and out[3] == 0.0
    assert same(out, per_resample(np.array([0, 1, 1, 2, 3]), s, y, np.array([[0, 0], [2, 2], [1, 1], [0, 3]])))
    assert np.isnan(GroupedAuroc(np.array([0, 1]), 2, [np.nan, np.nan], [True, False])(np.array([[0, 1]])))[0]
    assert grouped_auroc_ci(["a", "b", "c"], [0.3, 0.3, 0.3], [True, False, True], n_boot=50) == (0.5, 0.5)


def test_the_statistic_keeps_the_shape_of_the_index_array_and_blocks_do_not_change_it(monkeypatch):
    rng = np.random.default_rng(3)
    inverse, s, y = candidates(rng, "ties", 9)
    idx = rng.integers(0, 9, (4, 5, 9))
    whole = GroupedAuroc(inverse, 9, s, y)(idx)
    monkeypatch.setattr(auroc_batch, "_CELLS", 1)  # one resample per block
    assert whole.shape == (4, 5) and same(GroupedAuroc(inverse, 9, s, y)(idx), whole)
    assert curve_areas(np.array([[1.0, 0, 1, 0]]), np.array([[0.0, 1, 0, 1]]))[0] == 0.75  # scores.auroc's doctest


def test_the_auroc_interval_is_the_one_of_the_per_resample_code():
    """The whole BCa interval (resamples, jackknife, fallback) is unchanged, not just each resample's value."""
    rng = np.random.default_rng(11)
    for kind in ("continuous", "ties", "nan_inf"):
        inverse, s, y = candidates(rng, kind, 10)
        keys = np.array([f"img{g:02d}" for g in inverse])
        old = image_bootstrap(10, lambda idx, i=inverse, s=s, y=y: per_resample(i, s, y, idx), n_boot=300, seed=0)
        new = grouped_auroc_ci(keys, s, y, n_boot=300, seed=0)
        assert new == old or (math.isnan(new[0]) and math.isnan(old[0]))


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="one length"):
        GroupedAuroc([0, 1], 2, [0.1, 0.2, 0.3], [True, False, True])
    with pytest.raises(ValueError, match="group indices"):
        GroupedAuroc([0, 2], 2, [0.1, 0.2], [True, False])
