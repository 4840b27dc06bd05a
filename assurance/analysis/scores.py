"""Monitor scores in a campaign's readouts: AUROC per configuration and ROC curves.

A campaign stores every configuration's score per candidate (``candidates.score``; rejected iff
``score > threshold``). Unsafe candidates (``true_unsafe``) are the positives: the ROC curve is the
recall of the monitor (unsafe candidates rejected) against its false-positive rate (safe candidates
rejected) as the threshold sweeps, and the AUROC the probability that a random unsafe candidate
scores above a random safe one (ties count one half; Mann-Whitney). Intervals: percentile bootstrap
over images (candidates of one image are not independent), as the rest of the results table.

Runs recorded before scores existed have no ``score`` column: their AUROC is NaN, printed "-".
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from scipy.stats import rankdata

from assurance.analysis.intervals import percentile_interval, resample_indices

__all__ = ["auroc", "auroc_markdown", "auroc_table", "roc_curve"]


def auroc(scores: Any, unsafe: Any) -> float:
    """Area under the ROC curve of ``scores`` for the positives ``unsafe``; NaN without both classes.

    >>> auroc([0.1, 0.4, 0.35, 0.8], [False, False, True, True])
    0.75
    """
    s = np.asarray(scores, dtype=np.float64)
    y = np.asarray(unsafe, dtype=bool)
    ok = ~np.isnan(s)
    s, y = s[ok], y[ok]
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    if n_pos == 0 or n_neg == 0:
        return math.nan
    ranks = rankdata(s)  # average ranks: ties count one half
    return float((ranks[y].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def roc_curve(scores: Any, unsafe: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(fpr, tpr, thresholds)``: rejecting iff score > threshold, for every distinct score (and below all)."""
    s = np.asarray(scores, dtype=np.float64)
    y = np.asarray(unsafe, dtype=bool)
    ok = ~np.isnan(s)
    s, y = s[ok], y[ok]
    finite = s[np.isfinite(s)]
    below = (finite.min() - 1.0) if finite.size else 0.0
    thresholds = np.concatenate([[np.inf], np.unique(finite)[::-1], [below]])
    n_pos, n_neg = max(int(y.sum()), 1), max(int((~y).sum()), 1)
    tpr = np.array([(s[y] > t).sum() / n_pos for t in thresholds])
    fpr = np.array([(s[~y] > t).sum() / n_neg for t in thresholds])
    return fpr, tpr, thresholds


def _image_auroc_ci(g: pd.DataFrame, n_boot: int, seed: int, conf: float = 0.95) -> tuple[float, float]:
    keys = g["key"].to_numpy()
    uniq, inv = np.unique(keys, return_inverse=True)
    if len(uniq) < 2:
        return math.nan, math.nan
    members = [np.flatnonzero(inv == i) for i in range(len(uniq))]
    s, y = g["score"].to_numpy(float), g["true_unsafe"].to_numpy(bool)
    reps = np.empty(n_boot)
    for b, idx in enumerate(resample_indices(len(uniq), n_boot, seed)):
        rows = np.concatenate([members[i] for i in idx])
        reps[b] = auroc(s[rows], y[rows])
    return percentile_interval(reps, conf)


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
                row["auroc_lo95"], row["auroc_hi95"] = _image_auroc_ci(g, n_boot, seed)
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
