"""Where a campaign's time went: seconds by stage, summed over its tasks, and its wall time.

Each task records the time of its stages (reading, perturbing, segmenting the frame, finding the
candidates, judging them with every monitor configuration, shared work included) in its image rows;
the campaign log records each invocation's wall time. Worker time exceeds wall time by about the
number of workers.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from assurance.campaign import readouts
from el.base import userfiles

STAGES = ("read_s", "perturb_s", "segmentation_s", "candidates_s", "monitoring_s")
STAGE_NAMES = {"read_s": "read image", "perturb_s": "perturb", "segmentation_s": "segment frame",
               "candidates_s": "find candidates", "monitoring_s": "monitors (all configurations)",
               "other_s": "ground truth and clearance"}

__all__ = ["STAGES", "monitor_costs", "monitor_costs_markdown", "stage_table", "stages_markdown", "wall_seconds"]


def stage_table(run_dir: str | Path) -> pd.DataFrame:
    """One row per stage: total seconds over tasks, share of the tasks' time, median and p95 per task."""
    images = readouts.load_table(run_dir, "images")
    if images.empty:
        raise readouts.RunError(f"{run_dir}: no finished shard yet")
    ok = images[images["fault"].fillna("") == ""]
    # Every monitor configuration's row repeats its task's stage times: one row per task.
    tasks = ok.groupby(["perturbation", "severity", "key"], sort=False).agg(
        {**{s: "first" for s in STAGES}, "total_s": "max"})
    total = float(tasks["total_s"].sum())
    tasks["other_s"] = tasks["total_s"] - tasks[list(STAGES)].sum(axis=1)
    rows = []
    for s in (*STAGES, "other_s", "total_s"):
        col = tasks[s].astype(float)
        rows.append({"stage": STAGE_NAMES.get(s, "task total"), "seconds": float(col.sum()),
                     "share": float(col.sum()) / total if total > 0 else float("nan"),
                     "median_s": float(col.median()), "p95_s": float(col.quantile(0.95)), "tasks": int(len(col))})
    return pd.DataFrame(rows)


MAX_LOG_BYTES = 16 << 20
"""A run's ``log.jsonl``: one line of a few hundred bytes per campaign invocation."""


def wall_seconds(run_dir: str | Path) -> float | None:
    """Sum of the wall times of the run's campaign invocations (resumes included), None if unlogged."""
    path = Path(run_dir) / "log.jsonl"
    if not path.is_file():
        return None
    try:  # bounded: a line per campaign invocation (a link to /proc or a huge log is not read)
        text = userfiles.read_text(path, what="campaign log", max_bytes=MAX_LOG_BYTES)
    except userfiles.UserFileError:
        return None
    lines = [json.loads(line) for line in text.splitlines() if line.strip()]
    return float(sum(entry.get("seconds", 0.0) for entry in lines)) if lines else None


def stages_markdown(table: pd.DataFrame, wall: float | None = None) -> str:
    """The stage table as Markdown, with the campaign's wall time when known."""
    lines = ["| Stage | Worker seconds | Share | Median per task (s) | p95 per task (s) |", "|---|---|---|---|---|"]
    for _, r in table.iterrows():
        lines.append(f"| {r['stage']} | {r['seconds']:.1f} | {100 * r['share']:.1f}% | {r['median_s']:.2f} "
                     f"| {r['p95_s']:.2f} |")
    text = "\n".join(lines) + "\n"
    if wall is not None:
        n = int(table["tasks"].iloc[-1])
        text += f"\nWall time of the campaign: {wall / 60:.1f} min for {n} task(s) ({wall / max(n, 1):.2f} s a task).\n"
    return text


def monitor_costs(run_dir: str | Path) -> pd.DataFrame:
    """Per monitor configuration: monitoring seconds per candidate (what each configuration would have spent
    alone, shared work included, as the campaign attributes it), and the ratio to LHD's when LHD ran."""
    cands = readouts.load_table(run_dir, "candidates")
    if cands.empty:
        return pd.DataFrame(columns=["monitor", "candidates", "seconds_per_candidate", "x_lhd"])
    per = cands.groupby("monitor", sort=False)["seconds"].agg(["count", "mean"]).reset_index()
    lhd = per.loc[per["monitor"] == "lhd", "mean"]
    base = float(lhd.iloc[0]) if len(lhd) and float(lhd.iloc[0]) > 0 else float("nan")
    return pd.DataFrame({"monitor": per["monitor"], "candidates": per["count"].astype(int),
                         "seconds_per_candidate": per["mean"].astype(float),
                         "x_lhd": per["mean"].astype(float) / base})


def monitor_costs_markdown(table: pd.DataFrame) -> str:
    lines = ["| Monitor | Candidates | Seconds per candidate | x LHD |", "|---|---|---|---|"]
    for r in table.itertuples(index=False):
        ratio = "-" if r.x_lhd != r.x_lhd else f"{r.x_lhd:.2f}"
        lines.append(f"| `{r.monitor}` | {r.candidates} | {r.seconds_per_candidate:.4f} | {ratio} |")
    return "\n".join(lines) + "\n"
