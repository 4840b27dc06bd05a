"""The paper's findings asked of a results table, and of the published one, question by question.

Guerin et al. (ICRA 2022) draw four conclusions from their Table I. :func:`findings` asks each of
them of a campaign's results table (``assurance.analysis.table.results_table``) and, when given, of the
published results (``assurance.analysis.reference.load_reference``), so the comparison in a report is
computed rather than written by hand:

1. **CM vs default**: does the core model beat the default action (G_CM > 0) under every perturbation?
2. **CH**: does adding the class hierarchy raise the monitor's recall, and its FP rate?
3. **MCD**: what does Monte-Carlo dropout change (MCC, G*) and at what cost (overhead vs LHD alone)?
4. **Best configuration**: which configuration gives the highest G* under each perturbation?

Each answer is a small table (one row per perturbation, our figure beside the paper's) plus a one-line
verdict with counts, so agreement and disagreement can be read at a glance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["Finding", "findings", "findings_markdown"]

BASE = "lhd"  # every comparison is against LHD alone, as in the paper


@dataclass
class Finding:
    """One question: a verdict line and a table (perturbation rows; ours / paper columns)."""

    key: str
    question: str
    verdict: str
    table: pd.DataFrame


def _ordered_perturbations(df: pd.DataFrame) -> list[str]:
    return list(dict.fromkeys(df["perturbation"]))


def _value(df: pd.DataFrame | None, perturbation: str, monitor: str, column: str) -> float:
    if df is None or column not in df:
        return math.nan
    rows = df[(df["perturbation"] == perturbation) & (df["monitor"] == monitor)]
    if rows.empty:
        return math.nan
    v = rows[column].iloc[0]
    return math.nan if v is None or pd.isna(v) else float(v)


def _kind(monitor: str) -> str:
    return monitor.split(":", 1)[0]


def _count(values: list[float], predicate) -> tuple[int, int]:
    known = [v for v in values if not math.isnan(v)]
    return sum(bool(predicate(v)) for v in known), len(known)


def _cm_vs_default(ours: pd.DataFrame, paper: pd.DataFrame | None) -> Finding:
    rows = []
    for p in _ordered_perturbations(ours):
        rows.append({"perturbation": p,
                     "g_cm": _value(ours, p, BASE, "g_cm"),
                     "g_cm_lo95": _value(ours, p, BASE, "g_cm_lo95"),
                     "g_cm_paper": _value(paper, p, BASE, "g_cm")})
    t = pd.DataFrame(rows)
    pos, n = _count(list(t["g_cm"]), lambda v: v > 0)
    sure, _ = _count(list(t["g_cm_lo95"]), lambda v: v > 0)
    ppos, pn = _count(list(t["g_cm_paper"]), lambda v: v > 0)
    verdict = (f"G_CM > 0 under {pos} of {n} perturbations ({sure} with the 95% interval above 0); "
               f"paper: {ppos} of {pn}.")
    return Finding("cm_vs_default", "Does the core model beat the default action under every perturbation?",
                   verdict, t)


def _ch_effect(ours: pd.DataFrame, paper: pd.DataFrame | None) -> Finding:
    ch = [m for m in dict.fromkeys(ours["monitor"]) if _kind(m) == "lhd+ch"]
    rows = []
    for p in _ordered_perturbations(ours):
        for m in ch:
            row = {"perturbation": p, "monitor": m}
            for col in ("recall", "fp_rate"):
                row[f"d_{col}"] = _value(ours, p, m, col) - _value(ours, p, BASE, col)
                row[f"d_{col}_paper"] = _value(paper, p, m, col) - _value(paper, p, BASE, col)
            rows.append(row)
    t = pd.DataFrame(rows, columns=["perturbation", "monitor", "d_recall", "d_recall_paper",
                                    "d_fp_rate", "d_fp_rate_paper"])
    if t.empty:
        return Finding("ch", "Does the class hierarchy raise recall and FP rate?",
                       "no LHD+CH configuration in this run.", t)
    up_r, n = _count(list(t["d_recall"]), lambda v: v >= 0)
    up_f, _ = _count(list(t["d_fp_rate"]), lambda v: v >= 0)
    pup_r, pn = _count(list(t["d_recall_paper"]), lambda v: v >= 0)
    pup_f, _ = _count(list(t["d_fp_rate_paper"]), lambda v: v >= 0)
    verdict = (f"recall up (or equal) in {up_r} of {n} (perturbation, tau) cases, FP rate up in {up_f} of {n}; "
               f"paper: {pup_r} and {pup_f} of {pn}.")
    return Finding("ch", "Does the class hierarchy raise recall and FP rate?", verdict, t)


def _mcd_effect(ours: pd.DataFrame, paper: pd.DataFrame | None) -> Finding:
    mcd = [m for m in dict.fromkeys(ours["monitor"]) if _kind(m) == "lhd+mcd"]
    rows = []
    for p in _ordered_perturbations(ours):
        if not mcd:
            break
        row: dict[str, object] = {"perturbation": p}
        for who, df in (("", ours), ("_paper", paper)):
            d_mcc = [_value(df, p, m, "mcc") - _value(df, p, BASE, "mcc") for m in mcd]
            d_g = [_value(df, p, m, "g_star") - _value(df, p, BASE, "g_star") for m in mcd]
            base_cost = _value(df, p, BASE, "overhead_s")
            cost = [_value(df, p, m, "overhead_s") / base_cost if base_cost > 0 else math.nan for m in mcd]
            row[f"d_mcc_mean{who}"] = _nanmean(d_mcc)
            row[f"d_g_star_mean{who}"] = _nanmean(d_g)
            row[f"d_g_star_max_abs{who}"] = _nanmax_abs(d_g)
            row[f"cost_ratio{who}"] = _nanmean(cost)
        rows.append(row)
    t = pd.DataFrame(rows)
    if t.empty:
        return Finding("mcd", "What does MC dropout change, and at what cost?",
                       "no LHD+MCD configuration in this run.", t)
    verdict = (f"over {len(mcd)} MCD settings: mean change of G* {_fmt(_nanmean(list(t['d_g_star_mean'])))} "
               f"(paper {_fmt(_nanmean(list(t['d_g_star_mean_paper'])))}), of MCC "
               f"{_fmt(_nanmean(list(t['d_mcc_mean'])))} (paper {_fmt(_nanmean(list(t['d_mcc_mean_paper'])))}); "
               f"overhead x{_fmt(_nanmean(list(t['cost_ratio'])), 1)} that of LHD alone "
               f"(paper x{_fmt(_nanmean(list(t['cost_ratio_paper'])), 1)}).")
    return Finding("mcd", "What does MC dropout change, and at what cost?", verdict, t)


def _best_config(ours: pd.DataFrame, paper: pd.DataFrame | None) -> Finding:
    rows = []
    for p in _ordered_perturbations(ours):
        mons = list(dict.fromkeys(ours.loc[ours["perturbation"] == p, "monitor"]))
        best, best_p = _argmax(ours, p, mons), _argmax(paper, p, mons)
        rows.append({"perturbation": p, "best": best[0], "g_star": best[1],
                     "g_star_lhd": _value(ours, p, BASE, "g_star"),
                     "best_paper": best_p[0], "g_star_paper": best_p[1],
                     "g_star_lhd_paper": _value(paper, p, BASE, "g_star")})
    t = pd.DataFrame(rows)
    same = int(sum(_kind(str(a)) == _kind(str(b)) for a, b in zip(t["best"], t["best_paper"], strict=True)
                   if a is not None and b is not None))
    verdict = (f"the best configuration is of the same kind (LHD, LHD+CH, LHD+MCD, LHD+CH+MCD) as the paper's "
               f"under {same} of {len(t)} perturbations.")
    return Finding("best", "Which configuration gives the highest G* under each perturbation?", verdict, t)


def _argmax(df: pd.DataFrame | None, perturbation: str, monitors: list[str]) -> tuple[str | None, float]:
    vals = [(m, _value(df, perturbation, m, "g_star")) for m in monitors]
    vals = [(m, v) for m, v in vals if not math.isnan(v)]
    if not vals:
        return None, math.nan
    top = max(v for _, v in vals)
    # Of (nearly) equal G*, the first in grid order: the cheaper configuration.
    return next((m, v) for m, v in vals if v >= top - 1e-9)


def _nanmean(values: list[float]) -> float:
    arr = np.asarray(values, dtype=float)
    return float(np.nanmean(arr)) if np.isfinite(arr).any() else math.nan


def _nanmax_abs(values: list[float]) -> float:
    arr = np.abs(np.asarray(values, dtype=float))
    return float(np.nanmax(arr)) if np.isfinite(arr).any() else math.nan


def _fmt(v: object, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    if isinstance(v, float):
        return f"{v:+.{digits}f}" if digits == 3 else f"{v:.{digits}f}"
    return str(v)


def findings(ours: pd.DataFrame, paper: pd.DataFrame | None = None) -> list[Finding]:
    """The paper's four findings asked of ``ours`` (a results table) and of ``paper`` (same columns)."""
    if ours.empty:
        raise ValueError("the results table is empty")
    return [_cm_vs_default(ours, paper), _ch_effect(ours, paper), _mcd_effect(ours, paper),
            _best_config(ours, paper)]


def findings_markdown(items: list[Finding]) -> str:
    """The findings as Markdown: question, verdict, and its table."""
    out = []
    for i, f in enumerate(items, 1):
        out.append(f"**{i}. {f.question}** {f.verdict}\n")
        if f.table.empty:
            continue
        cols = list(f.table.columns)
        out.append("| " + " | ".join(cols) + " |")
        out.append("|" + "---|" * len(cols))
        for _, r in f.table.iterrows():
            cells = [(_fmt(v) if isinstance(v, float) and "ratio" not in c else
                      _fmt(v, 1) if isinstance(v, float) else (f"`{v}`" if c.startswith(("monitor", "best")) and v
                                                               else str(v)))
                     for c, v in r.items()]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out) + "\n"
