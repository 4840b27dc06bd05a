"""Monitor scores in a campaign's readouts: AUROC per configuration and ROC curves.

A campaign stores every configuration's score per candidate (``candidates.score``; rejected iff
``score > threshold``). Unsafe candidates (``true_unsafe``) are the positives: the ROC curve is the
recall of the monitor (unsafe candidates rejected) against its false-positive rate (safe candidates
rejected) as the threshold sweeps, and the AUROC the probability that a random unsafe candidate
scores above a random safe one (ties count one half; Mann-Whitney), both from scikit-learn
(``roc_auc_score``, ``roc_curve``). Intervals: the bootstrap over images (candidates of one image are not
independent; ``intervals.image_bootstrap``, BCa), as the rest of the results table.

Runs recorded before scores existed have no ``score`` column: their AUROC is NaN, printed "-".
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from sklearn import metrics as skm

from assurance.analysis.auroc_batch import GroupedAuroc
from assurance.analysis.intervals import image_bootstrap

__all__ = ["auroc", "auroc_markdown", "auroc_table", "grouped_auroc_ci", "roc_curve"]


def _clean(scores: Any, unsafe: Any) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(scores, dtype=np.float64)
    y = np.asarray(unsafe, dtype=bool)
    ok = ~np.isnan(s)
    return s[ok], y[ok]


def auroc(scores: Any, unsafe: Any) -> float:
    """Area under the ROC curve of ``scores`` for the positives ``unsafe`` (``sklearn.metrics.roc_auc_score``;
    ties count one half); NaN without both classes.

    >>> auroc([0.1, 0.4, 0.35, 0.8], [False, False, True, True])
    0.75
    """
    s, y = _clean(scores, unsafe)
    if y.all() or not y.any():
        return math.nan
    return float(skm.roc_auc_score(y, _finite_order(s)))


def _finite_order(s: np.ndarray) -> np.ndarray:
    """``s`` with +-inf replaced by finite values beyond the others (scikit-learn refuses infinities; the order,
    hence the curve, is the same)."""
    if np.isfinite(s).all():
        return s
    finite = s[np.isfinite(s)]
    lo, hi = (finite.min(), finite.max()) if finite.size else (0.0, 0.0)
    return np.where(s == np.inf, hi + 1.0, np.where(s == -np.inf, lo - 1.0, s))


def roc_curve(scores: Any, unsafe: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(fpr, tpr, thresholds)``: rejecting iff score > threshold, for every distinct score (and below all).

    From ``sklearn.metrics.roc_curve`` (which rejects iff score >= threshold): its point at a score is ours at
    the next lower one, so ours is its curve after a first point (0, 0) at +inf, thresholds shifted by one.
    A class with no candidate gets rate 0 throughout; infinite scores are counted directly.
    """
    s, y = _clean(scores, unsafe)
    finite = s[np.isfinite(s)]
    below = (finite.min() - 1.0) if finite.size else 0.0
    thresholds = np.concatenate([[np.inf], np.unique(finite)[::-1], [below]])
    if y.any() and not y.all() and np.isfinite(s).all():
        fpr, tpr, _ = skm.roc_curve(y, s, drop_intermediate=False)
        return np.concatenate([[0.0], fpr]), np.concatenate([[0.0], tpr]), thresholds
    # one class only, or infinite scores (which scikit-learn refuses): count the scores above each threshold
    def rate(values: np.ndarray) -> np.ndarray:
        return (len(values) - np.searchsorted(np.sort(values), thresholds, side="right")) / max(len(values), 1)

    return rate(s[~y]), rate(s[y]), thresholds


def grouped_auroc_ci(groups: Any, scores: Any, unsafe: Any, *, n_boot: int = 1000, seed: int = 0,
                     conf: float = 0.95) -> tuple[float, float]:
    """Bootstrap interval of the AUROC resampling whole groups (images, scenes: their candidates are not
    independent) with ``intervals.image_bootstrap``; ``(nan, nan)`` with fewer than two groups."""
    uniq, inv = np.unique(np.asarray(groups), return_inverse=True)
    if len(uniq) < 2:
        return math.nan, math.nan
    statistic = GroupedAuroc(inv, len(uniq), scores, unsafe)  # every sample at once, each equal to auroc()'s
    return image_bootstrap(len(uniq), statistic, n_boot=n_boot, conf=conf, seed=seed)


def auroc_table(candidates: pd.DataFrame, *, n_boot: int = 1000, seed: int = 0) -> pd.DataFrame:
    """One row per (perturbation, severity, monitor): candidates, unsafe ones, AUROC and its 95% interval."""
    cols = ["perturbation", "severity", "monitor", "candidates", "unsafe", "auroc", "auroc_lo95", "auroc_hi95"]
    if candidates is None or candidates.empty:
        return pd.DataFrame(columns=cols)
    has = "score" in candidates.columns
    rows = []
    for (pert, sev, mon), g in candidates.groupby(["perturbation", "severity", "monitor"], sort=False):
        row = {"perturbation": pert, "severity": int(sev), "monitor": mon, "candidates": len(g),
               "unsafe": int(g["true_unsafe"].sum()), "auroc": math.nan, "auroc_lo95": math.nan,
               "auroc_hi95": math.nan}
        if has and g["score"].notna().any():
            row["auroc"] = auroc(g["score"], g["true_unsafe"])
            if math.isfinite(row["auroc"]):
                row["auroc_lo95"], row["auroc_hi95"] = grouped_auroc_ci(g["key"], g["score"], g["true_unsafe"],
                                                                        n_boot=n_boot, seed=seed)
        rows.append(row)
    return pd.DataFrame(rows, columns=cols)


def _f(v: float) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.3f}"


def auroc_markdown(table: pd.DataFrame) -> str:
    """The AUROC table as Markdown ("-": no scores recorded, or only one class of candidate)."""
    lines = ["| Perturbation | Monitor | Candidates | Unsafe | AUROC [95% interval] |", "|---|---|---|---|---|"]
    for r in table.itertuples(index=False):
        ci = f" [{_f(r.auroc_lo95)}, {_f(r.auroc_hi95)}]" if math.isfinite(r.auroc_lo95) else ""
        lines.append(f"| {r.perturbation} (s{r.severity}) | `{r.monitor}` | {r.candidates} | {r.unsafe} | "
                     f"{_f(r.auroc)}{ci} |")
    return "\n".join(lines) + "\n"
