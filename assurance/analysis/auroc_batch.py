"""The AUROC of many resamples of groups at once, equal bit for bit to scikit-learn's ``roc_auc_score`` of each.

``assurance.analysis.scores.grouped_auroc_ci`` bootstraps the AUROC over images: per configuration 1000
resamples and a jackknife, each the AUROC of a few hundred candidates. One ``roc_auc_score`` call spends about
a millisecond validating its input, which was nearly all of ``uav-el table``'s time (30 s of 34 on the demo
run). ``GroupedAuroc`` computes a whole batch of resamples with a few array operations instead.

The arithmetic is scikit-learn's (``roc_curve`` with ``drop_intermediate``, then ``auc``), so the figures are
unchanged: a resample's curve is the cumulative counts of its positives and negatives at each distinct score it
holds (from the highest down), points whose second differences are both zero dropped, the counts divided by
the totals, and the area the trapezoid sum added up in numpy's order. Counts are exact integers in float64 (a
resample's curve depends only on how many times it draws each group), so every step rounds as scikit-learn's
does; tests/test_auroc_batch.py checks the equality against ``scores.auroc`` resample by resample.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["GroupedAuroc", "curve_areas"]

_CELLS = 1 << 20
"""Resamples are computed in blocks of about this many (resample, distinct score) cells: bounded memory."""


class GroupedAuroc:
    """AUROC of samples of whole groups (images, scenes), the statistic of ``intervals.image_bootstrap``.

    Parameters
    ----------
    inverse : array-like of int, shape (n_candidates,)
        The group of each candidate, ``0 .. n_groups - 1``.
    n_groups : int
        Number of groups.
    scores, unsafe : array-like, shape (n_candidates,)
        Monitor scores (NaN ones are left out, as ``scores.auroc`` does) and the positives.

    ``GroupedAuroc(...)(idx)`` maps group indices ``idx`` of shape ``(..., m)`` to the AUROC of each sample
    (shape ``(...)``), NaN where a sample lacks positives or negatives.
    """

    def __init__(self, inverse: Any, n_groups: int, scores: Any, unsafe: Any) -> None:
        s = np.asarray(scores, dtype=np.float64).reshape(-1)
        y = np.asarray(unsafe, dtype=bool).reshape(-1)
        g = np.asarray(inverse, dtype=np.intp).reshape(-1)
        if not s.shape == y.shape == g.shape:
            raise ValueError(f"inverse, scores and unsafe must have one length, got {g.size}, {s.size}, {y.size}")
        if g.size and (g.min() < 0 or g.max() >= n_groups):
            raise ValueError(f"group indices must lie in 0..{n_groups - 1}")
        ok = ~np.isnan(s)
        s, y, g = s[ok], y[ok], g[ok]
        values, col = np.unique(s, return_inverse=True)
        col = len(values) - 1 - col.reshape(-1)  # column 0: the highest score (the curve starts there)
        self.n_groups = int(n_groups)
        self.pos = np.zeros((self.n_groups, len(values)))  # per group: positives at each distinct score
        self.neg = np.zeros((self.n_groups, len(values)))
        np.add.at(self.pos, (g[y], col[y]), 1.0)
        np.add.at(self.neg, (g[~y], col[~y]), 1.0)

    def __call__(self, idx: np.ndarray) -> np.ndarray:
        idx = np.asarray(idx, dtype=np.intp)
        flat = idx.reshape(-1, idx.shape[-1])
        out = np.empty(len(flat))
        step = max(1, _CELLS // max(self.pos.shape[1], 1))
        for start in range(0, len(flat), step):
            rows = flat[start:start + step]
            draws = np.bincount((rows + self.n_groups * np.arange(len(rows))[:, None]).ravel(),
                                minlength=len(rows) * self.n_groups).reshape(len(rows), self.n_groups)
            weights = draws.astype(np.float64)  # how many times each resample drew each group
            out[start:start + step] = curve_areas(weights @ self.pos, weights @ self.neg)
        return out.reshape(idx.shape[:-1])


def _compact(keep: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """Each row's kept columns moved to its front, in order (the rest after them)."""
    order = np.argsort(~keep, axis=1, kind="stable")
    return [np.take_along_axis(a, order, axis=1) for a in arrays]


def curve_areas(pos: np.ndarray, neg: np.ndarray) -> np.ndarray:
    """Area under the ROC curve of each row of counts: ``pos[r, d]`` / ``neg[r, d]`` positives / negatives at
    the ``d``-th highest distinct score (exact integers as float64). NaN without both classes.

    ``sklearn.metrics.roc_auc_score`` of the row's candidates, rounding for rounding (module docstring).
    """
    n_rows, n_values = pos.shape
    total_pos, total_neg = pos.sum(axis=1), neg.sum(axis=1)
    present = (pos + neg) > 0
    tps, fps = _compact(present, np.cumsum(pos, axis=1), np.cumsum(neg, axis=1))  # the thresholds of the row
    n_points = present.sum(axis=1)[:, None]
    k = np.arange(n_values)
    keep = k < n_points
    if n_values > 2:  # drop_intermediate: interior points where neither count's second difference is nonzero
        bends = (np.diff(fps, 2, axis=1) != 0) | (np.diff(tps, 2, axis=1) != 0)
        keep[:, 1:-1] &= bends | (k[1:-1] >= n_points - 1) | (n_points <= 2)
    zero = np.zeros((n_rows, 1))
    keep = np.concatenate([np.ones((n_rows, 1), bool), keep], axis=1)  # the curve starts at (0, 0)
    tps, fps = _compact(keep, np.concatenate([zero, tps], axis=1), np.concatenate([zero, fps], axis=1))
    defined = (total_pos > 0) & (total_neg > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        fpr, tpr = fps / total_neg[:, None], tps / total_pos[:, None]
    terms = np.diff(fpr, axis=1) * (tpr[:, 1:] + tpr[:, :-1]) / 2.0  # numpy.trapezoid's, in its order
    n_terms = keep.sum(axis=1) - 1
    out = np.full(n_rows, np.nan)
    for n in np.unique(n_terms[defined]):  # each row summed alone (numpy's pairwise order depends on length)
        rows = defined & (n_terms == n)
        out[rows] = np.add.reduce(np.ascontiguousarray(terms[rows, :n]), axis=1)
    return out
