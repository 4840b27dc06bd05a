"""Ranking monitors across blocks: the Friedman test and the Nemenyi critical difference (Demsar, JMLR 2006).

The blocks are the perturbations of a run (or its scenes), the treatments the monitors, the measure one number
per (block, monitor) where higher is better (AUROC by default). Each block ranks the monitors (1 = best, ties
share the mean rank); the Friedman test (``scipy.stats.friedmanchisquare``) asks whether the mean ranks differ more
than chance allows; the Nemenyi post-hoc test calls two monitors different when their mean ranks differ by more
than the critical difference ``CD = q_alpha sqrt(k (k + 1) / (6 N))``, with ``q_alpha`` the studentized range
quantile over sqrt 2 (``scipy.stats.studentized_range``) for k monitors and N blocks. scipy alone: no other
dependency. The diagram draws each monitor at its mean rank and joins, by a bar, the groups no test tells apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from matplotlib.figure import Figure


@dataclass(frozen=True)
class Ranking:
    """Mean ranks (1 = best), the Friedman test and the Nemenyi critical difference over ``blocks`` blocks."""

    mean_ranks: pd.Series  # monitor -> mean rank, best first
    blocks: int
    statistic: float
    p_value: float
    cd: float
    alpha: float

    def different(self, a: str, b: str) -> bool:
        """Whether the Nemenyi test tells monitors ``a`` and ``b`` apart at ``alpha``."""
        return bool(abs(self.mean_ranks[a] - self.mean_ranks[b]) > self.cd)

    def cliques(self) -> list[tuple[str, ...]]:
        """Maximal groups of monitors (consecutive in rank order) whose ranks lie within CD of each other."""
        names = list(self.mean_ranks.index)
        r = self.mean_ranks.to_numpy(float)
        out: list[tuple[str, ...]] = []
        for i in range(len(names)):
            j = i
            while j + 1 < len(names) and r[j + 1] - r[i] <= self.cd:
                j += 1
            if j > i and not any(set(names[i:j + 1]) <= set(c) for c in out):
                out.append(tuple(names[i:j + 1]))
        return out


def nemenyi_cd(k: int, n: int, alpha: float = 0.05) -> float:
    """The Nemenyi critical difference of mean ranks for ``k`` treatments over ``n`` blocks.

    >>> round(nemenyi_cd(4, 10), 3)     # Demsar (2006), table 5: q_0.05 = 2.569 for k = 4
    1.483
    """
    from scipy.stats import studentized_range

    q = float(studentized_range.ppf(1.0 - alpha, k, np.inf)) / math.sqrt(2.0)
    return q * math.sqrt(k * (k + 1) / (6.0 * n))


def rank_monitors(measure: pd.DataFrame, alpha: float = 0.05) -> Ranking:
    """Rank the columns (monitors) of ``measure`` (rows: blocks; higher = better) over the complete rows.

    Needs at least 3 monitors and 2 complete blocks (ValueError otherwise)."""
    from scipy.stats import friedmanchisquare

    m = measure.dropna(axis=0, how="any")
    k, n = m.shape[1], m.shape[0]
    if k < 3:
        raise ValueError(f"the Friedman test needs at least 3 monitors, got {k}")
    if n < 2:
        raise ValueError(f"the Friedman test needs at least 2 blocks where every monitor has a value, got {n}")
    ranks = m.rank(axis=1, ascending=False, method="average")
    mean = ranks.mean(axis=0).sort_values(kind="mergesort")
    values = m.to_numpy(float)
    if np.all(values == values[:, :1]):  # every block ties every monitor: nothing to test
        stat, p = 0.0, 1.0
    else:
        res = friedmanchisquare(*[values[:, j] for j in range(k)])
        stat, p = float(res.statistic), float(res.pvalue)
    return Ranking(mean, n, stat, p, nemenyi_cd(k, n, alpha), alpha)


def cd_figure(r: Ranking, title: str = "") -> Figure:
    """The critical-difference diagram: mean ranks on an axis (1 at the left, best), bars over the cliques."""
    names = list(r.mean_ranks.index)
    k = len(names)
    half = (k + 1) // 2
    fig = Figure(figsize=(7.2, 1.6 + 0.28 * half))
    ax = fig.add_axes((0.03, 0.02, 0.94, 0.8 if title else 0.9))
    ax.set_xlim(0.5, k + 0.5)
    ax.set_ylim(-(half + 1.5), 1.6)
    ax.axis("off")
    ax.hlines(0, 1, k, color="k", lw=1)
    for i in range(1, k + 1):
        ax.vlines(i, 0, 0.25, color="k", lw=1)
        ax.text(i, 0.4, str(i), ha="center", va="bottom", fontsize=8)
    ax.hlines(1.25, 1, 1 + r.cd, color="k", lw=2)
    ax.text(1 + r.cd / 2, 1.35, f"CD = {r.cd:.2f}", ha="center", va="bottom", fontsize=8)
    for i, name in enumerate(names):
        x = float(r.mean_ranks[name])
        left = i < half
        y = -(i + 1) if left else -(k - i)
        end = 0.6 if left else k + 0.4
        ax.vlines(x, y, 0, color="k", lw=0.8)
        ax.hlines(y, min(x, end), max(x, end), color="k", lw=0.8)
        ax.text(end - 0.05 if left else end + 0.05, y, f"{name} ({x:.2f})", ha="right" if left else "left",
                va="center", fontsize=7)
    for j, clique in enumerate(r.cliques()):
        lo, hi = float(r.mean_ranks[clique[0]]), float(r.mean_ranks[clique[-1]])
        ax.hlines(-0.35 - 0.25 * j, lo - 0.03, hi + 0.03, color="tab:red", lw=3)
    if title:
        fig.suptitle(title, fontsize=8)
    return fig
