"""The results table of a campaign run (docs/architecture.md section 4.5; the paper's Table I layout).

``results_table(run)`` turns the readouts store into one row per (perturbation, severity, monitor)
with the CSV columns of ``assurance.analysis.metrics.RESULT_COLUMNS`` (plus ``faults``: images whose
evaluation failed and are left out of the figures). ``to_markdown`` lays it out as the paper's
Table I with 95% intervals; ``compare`` puts it beside the published figures.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from assurance.analysis.metrics import RESULT_COLUMNS, ImageReadout, ScenarioMetrics, rows_to_frame
from assurance.analysis.reference import load_reference
from assurance.campaign import readouts
from assurance.campaign.task import scenario_pairs
from assurance.files import atomic_write_bytes

PAPER_FIGURES = ("g_cm", "mcc", "f1", "precision", "recall", "fp_rate", "g_rm", "overhead_s", "g_star")
HEADERS = {"g_cm": "G_CM", "mcc": "MCC", "f1": "F1", "precision": "Precision", "recall": "Recall",
           "fp_rate": "FP rate", "g_rm": "G_RM", "overhead_s": "Overhead (s)", "g_star": "G*",
           "unsafe_landing_rate": "Unsafe landings", "unsafe_landing_ub95": "UB95"}


def image_readouts(images: pd.DataFrame, candidates: pd.DataFrame) -> dict[tuple[str, int, str], list[ImageReadout]]:
    """Per scenario (perturbation, severity, monitor): the ImageReadouts of its non-faulted images."""
    out: dict[tuple[str, int, str], list[ImageReadout]] = {}
    ok = images[images["fault"].fillna("") == ""] if len(images) else images
    groups = {}
    if len(candidates):
        for key, g in candidates.groupby(["perturbation", "severity", "monitor", "key"], sort=False):
            g = g.sort_values("rank")
            groups[key] = (g["true_unsafe"].to_numpy(bool), ~g["accepted"].to_numpy(bool))
    for row in ok.itertuples(index=False):
        scen = (row.perturbation, int(row.severity), row.monitor)
        unsafe, rejected = groups.get((*scen, row.key), (np.zeros(0, bool), np.zeros(0, bool)))
        h_top = None if row.candidates == 0 else float(row.h_top)
        out.setdefault(scen, []).append(ImageReadout(
            unsafe=unsafe, rejected=rejected, h_default=float(row.h_default), h_top=h_top,
            h_decision=float(row.h_decision), overhead_s=float(row.overhead_s), image_id=row.key,
        ))
    return out


def results_table(run_dir: str | Path, *, n_boot: int = 2000, seed: int = 0, images: pd.DataFrame | None = None,
                  candidates: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per scenario, columns ``RESULT_COLUMNS`` + ``faults``, in the campaign's order.

    ``images`` / ``candidates``: the run's tables (``readouts.load_table``) where the caller has them already,
    so that a command reads each once."""
    man = readouts.read_manifest(run_dir)
    images = readouts.load_table(run_dir, "images") if images is None else images
    candidates = readouts.load_table(run_dir, "candidates") if candidates is None else candidates
    if images.empty:
        raise readouts.RunError(f"{run_dir}: no finished shard yet")
    per_scen = image_readouts(images, candidates)
    faults = images[images["fault"].fillna("") != ""]
    cfg = man["config"]
    rows = []
    order = _scenario_order(cfg)
    for pert, sev in order:
        here = faults[(faults["perturbation"] == pert) & (faults["severity"] == sev)] if len(faults) else faults
        for mon in cfg["monitors"]:  # a task's fault (monitor "") counts for every configuration, one's for it alone
            n_fault = int(here["monitor"].fillna("").isin(["", mon]).sum()) if len(here) else 0
            recs = per_scen.get((pert, sev, mon), [])
            if not recs and not n_fault:
                continue
            sm = ScenarioMetrics(pert, sev, mon, n_boot=n_boot, seed=seed)
            sm.extend(recs)
            row = sm.compute()
            row["faults"] = n_fault
            rows.append(row)
    df = rows_to_frame(rows)
    df["faults"] = [r["faults"] for r in rows]
    return df


def _scenario_order(cfg: dict[str, Any]) -> list[tuple[str, int]]:
    return scenario_pairs(cfg["perturbations"], cfg["severities"], cfg.get("severity_caps"))


def write_csv(df: pd.DataFrame, path: str | Path) -> None:
    atomic_write_bytes(path, df.to_csv(index=False, float_format="%.6g").encode())


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    return f"{v:.{digits}f}"


def _cell(row: pd.Series, name: str, intervals: bool) -> str:
    digits = 2 if name == "overhead_s" else 3
    text = _fmt(row[name], digits)
    lo, hi = row.get(f"{name}_lo95"), row.get(f"{name}_hi95")
    if intervals and lo is not None and not (isinstance(lo, float) and math.isnan(lo)):
        text += f" [{_fmt(lo, digits)}, {_fmt(hi, digits)}]"
    return text


def to_markdown(df: pd.DataFrame, *, intervals: bool = True) -> str:
    """The paper's Table I layout: one block per perturbation, one line per monitor configuration."""
    cols = ["Perturbation", "Monitor", "Images", "Candidates", *(HEADERS[c] for c in PAPER_FIGURES),
            "Unsafe landings (UB95)"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    last = None
    for _, r in df.iterrows():
        pert = f"{r['perturbation']} (s{r['severity']})"
        shown = pert if pert != last else ""
        last = pert
        cells = [shown, f"`{r['monitor']}`", str(int(r["images"])), str(int(r["candidates"]))]
        cells += [_cell(r, c, intervals) for c in PAPER_FIGURES]
        cells.append(f"{_fmt(r['unsafe_landing_rate'])} ({_fmt(r['unsafe_landing_ub95'])})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def compare(df: pd.DataFrame) -> pd.DataFrame:
    """Our figures beside the paper's (Guerin et al., ICRA 2022) for the same perturbation and monitor."""
    ref = load_reference()[["perturbation", "monitor", *PAPER_FIGURES]]
    ours = df[["perturbation", "severity", "monitor", *PAPER_FIGURES]]
    merged = ours.merge(ref, on=["perturbation", "monitor"], how="left", suffixes=("", "_paper"))
    return merged


def compare_markdown(merged: pd.DataFrame) -> str:
    cols = ["Perturbation", "Monitor", *(f"{HEADERS[c]} ours / paper" for c in PAPER_FIGURES)]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in merged.iterrows():
        cells = [f"{r['perturbation']} (s{r['severity']})", f"`{r['monitor']}`"]
        for c in PAPER_FIGURES:
            digits = 2 if c == "overhead_s" else 3
            cells.append(f"{_fmt(r[c], digits)} / {_fmt(r[c + '_paper'], digits)}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


__all__ = ["RESULT_COLUMNS", "compare", "compare_markdown", "results_table", "to_markdown", "write_csv"]
