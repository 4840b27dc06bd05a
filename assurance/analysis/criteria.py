"""Threshold criteria by name: how a monitor's threshold is chosen, recorded beside the threshold it chose.

Two levels (a monitor rejects a candidate iff its score > threshold):

- **system level**, on a sweep of a campaign's replayed decisions (``assurance.analysis.sweep``): the paper's
  choice, ``fewest-unsafe`` (fewest unsafe landings over all perturbations; ties: larger G*, lower miss rate),
  and ``g-star`` (the largest mean G*; ties: fewer unsafe landings);
- **candidate level**, on candidates' scores and truth (unsafe = the positive class, rejected = flagged): the
  calibration's ``guarantee`` (the largest threshold with P(accept an unsafe candidate) <= miss rate at a
  confidence: order statistic + Clopper-Pearson, ``assurance.analysis.guarantee``), and the runtime-monitor
  benchmark's ``f1`` (largest F1), ``g-mean`` (largest sqrt(TPR x TNR)) and ``tnr-at-recall`` (the largest
  threshold whose recall of unsafe candidates is >= the stated recall, i.e. the best TNR at that recall)
  (Guerin et al., UAI 2024). Ties among candidate-level thresholds go to the smaller (more cautious) one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from assurance.analysis.guarantee import calibrate_threshold
from assurance.analysis.sweep import Choice, SweepError, default_thresholds, monitor_rows, sweep, totals
from assurance.analysis.sweep_report import scored_monitors, sweep_run

SYSTEM = ("fewest-unsafe", "g-star")
CANDIDATE = ("guarantee", "f1", "g-mean", "tnr-at-recall")
CRITERIA = SYSTEM + CANDIDATE
DESCRIPTION = {
    "fewest-unsafe": "fewest unsafe landings over the run's perturbations (the paper's system-level choice)",
    "g-star": "largest mean G* over the run's images (ties: fewer unsafe landings)",
    "guarantee": "calibration: P(accept an unsafe candidate) <= miss rate with the stated confidence "
                 "(order statistic + Clopper-Pearson)",
    "f1": "largest F1 of flagging unsafe candidates",
    "g-mean": "largest G-mean sqrt(TPR x TNR) of flagging unsafe candidates",
    "tnr-at-recall": "largest threshold whose recall of unsafe candidates is >= the stated recall (best TNR there)",
}


def check_criterion(name: str) -> str:
    """``name`` when it is a known criterion, else ValueError listing them."""
    if name not in CRITERIA:
        raise ValueError(f"unknown threshold criterion {name!r} (known: {', '.join(CRITERIA)})")
    return name


def _grid(scores: np.ndarray, points: int = 2000) -> np.ndarray:
    s = np.unique(scores[np.isfinite(scores)])
    if s.size > points:
        s = np.unique(np.quantile(s, np.linspace(0.0, 1.0, points), method="nearest"))
    below = (s[0] - max(1e-9, abs(s[0]) * 1e-9)) if s.size else 0.0
    return np.concatenate([[below], s])


def rates(scores: Any, unsafe: Any, thresholds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(TP, FP, FN) counts at each threshold (unsafe = positive, rejected iff score > threshold)."""
    s, y = np.asarray(scores, np.float64), np.asarray(unsafe, bool)
    rejected = s[None, :] > thresholds[:, None]
    tp = (rejected & y).sum(axis=1)
    fp = (rejected & ~y).sum(axis=1)
    return tp, fp, y.sum() - tp


def candidate_threshold(criterion: str, scores: Any, unsafe: Any, *, recall: float = 0.95, miss_rate: float = 0.05,
                        confidence: float = 0.95) -> tuple[float, str]:
    """The threshold a candidate-level criterion picks on these candidates, and a note of what it achieves."""
    check_criterion(criterion)
    if criterion in SYSTEM:
        raise ValueError(f"criterion {criterion!r} chooses on replayed decisions (uav-el sweep), not on candidates")
    s, y = np.asarray(scores, np.float64), np.asarray(unsafe, bool)
    if not y.any():
        raise ValueError(f"criterion {criterion!r}: no truly unsafe candidate to choose a threshold on")
    if criterion == "guarantee":
        res = calibrate_threshold(s[y], miss_rate, confidence)
        return float(res["threshold"]), f"miss rate <= {miss_rate:g} at confidence {confidence:g}"
    ts = _grid(s)
    tp, fp, fn = rates(s, y, ts)
    neg = max(int((~y).sum()), 1)
    tpr, tnr = tp / y.sum(), 1.0 - fp / neg
    if criterion == "tnr-at-recall":
        ok = np.flatnonzero(tpr >= recall - 1e-12)
        i = int(ok[-1])  # the largest threshold still at that recall (ts ascending): its TNR is the best
        return float(ts[i]), f"recall {tpr[i]:.3f} >= {recall:g}, TNR {tnr[i]:.3f}"
    value = (2 * tp / np.maximum(2 * tp + fp + fn, 1)) if criterion == "f1" else np.sqrt(tpr * tnr)
    i = int(np.argmax(value))  # the first (smallest) threshold of the best value
    return float(ts[i]), f"{criterion} {value[i]:.3f} (recall {tpr[i]:.3f}, TNR {tnr[i]:.3f})"


def system_choice(table: pd.DataFrame, criterion: str) -> tuple[float, str]:
    """The threshold a system-level criterion picks on one (monitor, walk)'s sweep rows, and a note."""
    t = totals(table)
    if criterion == "fewest-unsafe":
        keys, asc = ["unsafe_landings", "g_star", "miss_rate"], [True, False, True]
    elif criterion == "g-star":
        keys, asc = ["g_star", "unsafe_landings", "miss_rate"], [False, True, True]
    else:
        raise ValueError(f"criterion {criterion!r} is not a system-level one ({', '.join(SYSTEM)})")
    best = t.sort_values(keys, ascending=asc, kind="mergesort").iloc[0]
    return float(best["threshold"]), f"{int(best['unsafe_landings'])} unsafe landings, mean G* {best['g_star']:.3f}"


def criterion_thresholds(images: pd.DataFrame, candidates: pd.DataFrame, monitor: str, criteria: Sequence[str], *,
                         walk: str | None = None, recall: float = 0.95, miss_rate: float = 0.05,
                         confidence: float = 0.95) -> tuple[pd.DataFrame, dict[str, tuple[float, str]]]:
    """One monitor's sweep over its score grid plus each criterion's threshold, and ``{criterion: (t, note)}``.

    Candidate-level criteria choose on every candidate of the run (all perturbations); a criterion that cannot
    choose (no unsafe candidate) gives NaN and its reason."""
    _, ca = monitor_rows(images, candidates, monitor)
    scores, unsafe = ca["score"].to_numpy(float), ca["true_unsafe"].astype(bool).to_numpy()
    picked: dict[str, tuple[float, str]] = {}
    for c in criteria:
        if check_criterion(c) in CANDIDATE:
            try:
                picked[c] = candidate_threshold(c, scores, unsafe, recall=recall, miss_rate=miss_rate,
                                                confidence=confidence)
            except ValueError as exc:
                picked[c] = (math.nan, str(exc))
    ts = np.unique(np.concatenate([default_thresholds(scores),
                                   [t for t, _ in picked.values() if math.isfinite(t)]]))
    table = sweep(images, candidates, monitor, thresholds=ts, walks=[walk] if walk else None)
    for c in criteria:
        if c in SYSTEM:
            picked[c] = system_choice(table, c)
    return table, picked


def sweep_by_criterion(images: pd.DataFrame, candidates: pd.DataFrame, monitors: Sequence[str] | None,
                       walks: Sequence[str] | None, criterion: str, *, recall: float = 0.95, miss_rate: float = 0.05,
                       confidence: float = 0.95) -> tuple[pd.DataFrame, list[Any]]:
    """``uav-el sweep --criterion``: every (or the named) scored configuration swept, each (monitor, walk)'s
    threshold chosen by ``criterion`` (a :class:`assurance.analysis.sweep.Choice`), best first as the sweep's."""
    check_criterion(criterion)
    if criterion == "fewest-unsafe":
        return sweep_run(images, candidates, monitors, walks)
    names = list(monitors) if monitors else scored_monitors(candidates)
    if not names:
        raise SweepError("no configuration of the run carries candidate scores (monitor 'none' has none)")
    tables, choices = [], []
    for m in names:
        for w in walks or [None]:
            table, picked = criterion_thresholds(images, candidates, m, [criterion], walk=w, recall=recall,
                                                 miss_rate=miss_rate, confidence=confidence)
            t, note = picked[criterion]
            if not math.isfinite(t):
                raise SweepError(f"{m}: {note}")
            row = totals(table)
            row = row[row["threshold"] == t].iloc[0]
            tables.append(table)
            choices.append(Choice(m, str(row["walk"]), t, int(row["unsafe_landings"]), int(row["images"]),
                                  float(row["g_star"]), float(row["miss_rate"]), float(row["fp_rate"])))
    choices.sort(key=lambda c: (c.unsafe_landings, -c.g_star, c.miss_rate))
    return pd.concat(tables, ignore_index=True), choices


def criterion_line(criterion: str, recall: float = 0.95) -> str:
    """The Markdown line a sweep or benchmark writes: which criterion chose the thresholds."""
    what = DESCRIPTION[check_criterion(criterion)].replace("the stated recall", f"{recall:g}")
    return f"Thresholds chosen by criterion `{criterion}`: {what}."
