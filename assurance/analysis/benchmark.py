"""The monitor benchmark of a campaign run (``uav-el benchmark``): every monitor, every criterion, every block.

Per (monitor, perturbation): the AUROC of its candidate scores (unsafe = positive), and at each threshold
criterion's threshold (``assurance.analysis.criteria``, chosen once per monitor on all the run's candidates or
decisions): miss rate, false-alarm (FP) rate, unsafe landings and G*. Then the monitors ranked across blocks
(perturbations or scenes) by AUROC (or G* at a criterion's threshold) with the Friedman test and the Nemenyi
critical difference (``assurance.analysis.ranking``).
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from assurance.analysis.criteria import criterion_line, criterion_thresholds
from assurance.analysis.ranking import Ranking, cd_figure, rank_monitors
from assurance.analysis.scores import auroc
from assurance.files import atomic_write_bytes

DEFAULT_CRITERIA = ("fewest-unsafe", "g-star", "f1", "g-mean", "tnr-at-recall")


def benchmark_table(images: pd.DataFrame, candidates: pd.DataFrame, monitors: Sequence[str],
                    criteria: Sequence[str] = DEFAULT_CRITERIA, *, recall: float = 0.95, miss_rate: float = 0.05,
                    confidence: float = 0.95) -> pd.DataFrame:
    """One row per (monitor, criterion, perturbation): threshold, AUROC, miss and FP rates, unsafe landings, G*."""
    rows = []
    for m in monitors:
        table, picked = criterion_thresholds(images, candidates, m, criteria, recall=recall, miss_rate=miss_rate,
                                             confidence=confidence)
        ca = candidates[candidates["monitor"] == m]
        au = {p: auroc(g["score"].to_numpy(float), g["true_unsafe"].astype(bool).to_numpy())
              for p, g in ca.groupby("perturbation", sort=True)}
        for c in criteria:
            t, note = picked[c]
            at = table[table["threshold"] == t] if math.isfinite(t) else table.iloc[0:0]
            for p in sorted(au):
                r = at[at["perturbation"] == p]
                one = r.iloc[0] if len(r) else None
                rows.append({
                    "monitor": m, "criterion": c, "threshold": t, "note": note, "perturbation": p, "auroc": au[p],
                    "images": int(one["images"]) if one is not None else 0,
                    **{k: (float(one[k]) if one is not None else math.nan)
                       for k in ("miss_rate", "fp_rate", "unsafe_landings", "g_star")},
                })
    return pd.DataFrame(rows)


def block_measure(table: pd.DataFrame, candidates: pd.DataFrame, monitors: Sequence[str], *, by: str = "perturbation",
                  measure: str = "auroc", criterion: str = "fewest-unsafe") -> pd.DataFrame:
    """Blocks x monitors of ``measure`` (higher = better): ``auroc`` per perturbation or per scene (``by="scene"``:
    a scene's candidates under every perturbation), or ``g_star`` at ``criterion``'s threshold per perturbation."""
    if measure == "g_star":
        if by != "perturbation":
            raise ValueError("G* is ranked per perturbation (--blocks perturbation)")
        sub = table[table["criterion"] == criterion]
        return sub.pivot(index="perturbation", columns="monitor", values="g_star")[list(monitors)]
    if measure != "auroc":
        raise ValueError(f"unknown measure {measure!r} (auroc, g_star)")
    key = "perturbation" if by == "perturbation" else "key"
    ca = candidates[candidates["monitor"].isin(monitors)]
    out = {m: {b: auroc(g["score"].to_numpy(float), g["true_unsafe"].astype(bool).to_numpy())
               for b, g in d.groupby(key, sort=True)} for m, d in ca.groupby("monitor", sort=True)}
    return pd.DataFrame(out)[list(monitors)]


def _cell(v: float, fmt: str = ".3f") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def benchmark_markdown(table: pd.DataFrame, ranking: Ranking | None, why_not: str, *, blocks: str, measure: str,
                       deployed: str | None, recall: float) -> str:
    """The comparison as Markdown: per-perturbation AUROC, each criterion's totals, the ranking, the deployed one."""
    perts = sorted(table["perturbation"].unique())
    au = table.drop_duplicates(["monitor", "perturbation"]).pivot(index="monitor", columns="perturbation",
                                                                  values="auroc")
    lines = ["## AUROC per perturbation (unsafe candidates = positive)", "",
             "| monitor | " + " | ".join(perts) + " | mean |", "|" + "---|" * (len(perts) + 2)]
    for m, r in au.iterrows():
        lines.append(f"| {m} | " + " | ".join(_cell(r[p]) for p in perts) + f" | {_cell(float(np.nanmean(r)))} |")
    for c, sub in table.groupby("criterion", sort=False):
        lines += ["", f"## At each monitor's `{c}` threshold", "", criterion_line(str(c), recall), "",
                  "| monitor | threshold | miss rate | FP rate | unsafe landings | mean G* | " + " | ".join(
                      f"unsafe {p}" for p in perts) + " |", "|" + "---|" * (6 + len(perts))]
        for m, d in sub.groupby("monitor", sort=False):
            d = d.set_index("perturbation")
            n = d["images"].sum()
            g = float(np.average(d["g_star"], weights=d["images"])) if n else math.nan
            lines.append(f"| {m} | {_cell(float(d['threshold'].iloc[0]), '.4g')} | {_cell(d['miss_rate'].mean())} | "
                         f"{_cell(d['fp_rate'].mean())} | {_cell(d['unsafe_landings'].sum(), '.0f')} / {int(n)} | "
                         f"{_cell(g)} | " + " | ".join(_cell(d.loc[p, 'unsafe_landings'], '.0f') for p in perts)
                         + " |")
    lines += ["", f"## Ranking by {measure} across {blocks}s (Friedman test, Nemenyi critical difference)", ""]
    if ranking is None:
        lines.append(f"No ranking: {why_not}.")
    else:
        lines += [f"Friedman chi2 = {ranking.statistic:.3f}, p = {ranking.p_value:.4g} over {ranking.blocks} "
                  f"{blocks}s; Nemenyi CD = {ranking.cd:.3f} at alpha {ranking.alpha:g} (cd.png).", "",
                  "| rank | monitor | mean rank |", "|---|---|---|"]
        lines += [f"| {i} | {m} | {v:.2f} |" for i, (m, v) in enumerate(ranking.mean_ranks.items(), 1)]
        lines += ["", "Groups not told apart: " + ("; ".join("{" + ", ".join(c) + "}" for c in ranking.cliques())
                                                 or "none (every pair differs)") + "."]
        lines += _deployed_lines(ranking, deployed)
    return "\n".join(lines) + "\n"


def _deployed_lines(r: Ranking, deployed: str | None) -> list[str]:
    if deployed is None or deployed not in r.mean_ranks.index:
        return []
    better = [m for m in r.mean_ranks.index if r.mean_ranks[m] < r.mean_ranks[deployed] and r.different(m, deployed)]
    if not better:
        return ["", f"No monitor ranks significantly above the deployed `{deployed}`."]
    return ["", f"Ranks significantly above the deployed `{deployed}`: {', '.join(better)}. Reported, not deployed: "
                "changing the deployed monitor is a release decision on the test split (uav-el campaign, evidence)."]


def write_benchmark(out: Path, table: pd.DataFrame, measure_table: pd.DataFrame, *, blocks: str, measure: str,
                    deployed: str | None, recall: float, alpha: float = 0.05) -> tuple[str, Ranking | None]:
    """Write benchmark.csv, blocks.csv, benchmark.md and (when the test can run) cd.png into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "benchmark.csv", table.to_csv(index=False).encode())
    atomic_write_bytes(out / "blocks.csv", measure_table.to_csv().encode())
    try:
        ranking, why = rank_monitors(measure_table, alpha), ""
    except ValueError as exc:
        ranking, why = None, str(exc)
    md = benchmark_markdown(table, ranking, why, blocks=blocks, measure=measure, deployed=deployed, recall=recall)
    atomic_write_bytes(out / "benchmark.md", md.encode())
    if ranking is not None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        fig = cd_figure(ranking, f"mean rank by {measure} over {ranking.blocks} {blocks}s (1 = best); Friedman "
                                 f"p = {ranking.p_value:.3g}; bars: groups within the Nemenyi CD")
        FigureCanvasAgg(fig)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
        atomic_write_bytes(out / "cd.png", buf.getvalue())
    return md, ranking
