"""The threshold sweep of a run as files: sweep.csv (every threshold), sweep.md (the choice) and sweep.png."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from assurance.analysis.sweep import Choice, SweepError, choose, sweep, totals
from assurance.files import atomic_write_bytes


def scored_monitors(candidates: pd.DataFrame) -> list[str]:
    """Configurations of a run whose candidates carry finite scores and a finite threshold."""
    if "score" not in candidates.columns:
        return []
    ok = candidates.groupby("monitor").apply(
        lambda d: bool(np.isfinite(d["score"].to_numpy(float)).any()
                       and np.isfinite(d["threshold"].to_numpy(float)).all()), include_groups=False)
    return sorted(m for m, v in ok.items() if v)


def sweep_run(images: pd.DataFrame, candidates: pd.DataFrame, monitors: Sequence[str] | None = None,
              walks: Sequence[str] | None = None) -> tuple[pd.DataFrame, list[Choice]]:
    """Sweep every (or the named) scored configuration under ``walks`` (default: each one's own); the
    choice of each (monitor, walk), best first."""
    names = list(monitors) if monitors else scored_monitors(candidates)
    if not names:
        raise SweepError("no configuration of the run carries candidate scores (monitor 'none' has none)")
    table = pd.concat([sweep(images, candidates, m, walks=walks) for m in names], ignore_index=True)
    pairs = table[["monitor", "walk"]].drop_duplicates().itertuples(index=False)
    choices = sorted((choose(table[(table["monitor"] == m) & (table["walk"] == w)]) for m, w in pairs),
                     key=lambda c: (c.unsafe_landings, -c.g_star, c.miss_rate))
    return table, choices


def choice_markdown(table: pd.DataFrame, choices: Sequence[Choice]) -> str:
    """The chosen threshold of each monitor beside its run threshold, unsafe landings per perturbation."""
    perts = sorted(table["perturbation"].unique())
    head = ["monitor", "walk", "threshold", "miss rate", "FP rate", "mean G*", *perts, "total"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    tot = totals(table)
    for c in choices:
        sub = table[(table["monitor"] == c.monitor) & (table["walk"] == c.walk)]
        run_t = float(sub["run_threshold"].iloc[0]) if (sub["run_walk"] == c.walk).all() else np.nan
        for label, t in (("chosen", c.threshold), ("run", run_t)):
            if not np.isfinite(t):
                continue
            rows = sub[sub["threshold"] == t].set_index("perturbation")
            tt = tot[(tot["monitor"] == c.monitor) & (tot["walk"] == c.walk) & (tot["threshold"] == t)].iloc[0]
            cells = [f"{c.monitor} ({label})", c.walk, f"{t:.4g}", f"{tt['miss_rate']:.3f}", f"{tt['fp_rate']:.3f}",
                     f"{tt['g_star']:.3f}", *(str(int(rows.loc[p, 'unsafe_landings'])) for p in perts),
                     f"{int(tt['unsafe_landings'])} / {int(tt['images'])}"]
            lines.append("| " + " | ".join(cells) + " |")
    best = choices[0]
    lines += ["", f"Fewest unsafe landings: `{best.monitor}` walked by {best.walk} at threshold {best.threshold:.6g} "
                  f"({best.unsafe_landings} of {best.images} decisions unsafe, mean G* {best.g_star:.3f})."]
    return "\n".join(lines) + "\n"


def sweep_figure(table: pd.DataFrame, choices: Sequence[Choice]) -> Figure:
    """Unsafe landings over all perturbations against each monitor's FP rate (one curve per monitor)."""
    fig = Figure(figsize=(6.9, 3.6))
    ax = fig.add_subplot(1, 1, 1)
    tot = totals(table)
    for c in choices:
        d = tot[(tot["monitor"] == c.monitor) & (tot["walk"] == c.walk)].sort_values("fp_rate")
        line, = ax.plot(d["fp_rate"], d["unsafe_landings"], label=f"{c.monitor} ({c.walk} walk)", lw=1.4)
        pick = d[d["threshold"] == c.threshold].iloc[0]
        ax.plot([pick["fp_rate"]], [pick["unsafe_landings"]], "o", color=line.get_color())
    ax.set_xlabel("FP rate (safe candidates rejected, mean over perturbations)")
    ax.set_ylabel("unsafe landings (all perturbations)")
    ax.set_title("Threshold sweep: dots mark each monitor's chosen threshold", fontsize=9)
    ax.legend(fontsize=7, frameon=False)
    ax.grid(alpha=0.3)
    return fig


def write_sweep(out: Path, table: pd.DataFrame, choices: Sequence[Choice], note: str = "") -> str:
    """Write sweep.csv, sweep.md and sweep.png into ``out`` (atomically) and return the Markdown; ``note``: a last
    line (the threshold criterion)."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "sweep.csv", table.to_csv(index=False).encode())
    md = choice_markdown(table, choices) + (f"\n{note}\n" if note else "")
    atomic_write_bytes(out / "sweep.md", md.encode())
    fig = sweep_figure(table, choices)
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
    atomic_write_bytes(out / "sweep.png", buf.getvalue())
    return md
