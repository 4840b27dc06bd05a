"""The report's monitor-benchmark section (``uav-el evidence --benchmark DIR``): what ``uav-el benchmark`` found
on validation scenes, re-derived from its tables.

The section reads only ``benchmark.csv`` and ``blocks.csv`` (bounded reads, checked columns, numbers only) and
recomputes the Friedman test, the Nemenyi critical difference and the diagram from ``blocks.csv`` itself; the
folder's Markdown and PNG are never shown, so a supplied file cannot put its own text or picture in the report.
The benchmark is not part of the signed evidence chain and never moves the gate: the section says so and gives
the SHA-256 of the two files it read.
"""

from __future__ import annotations

import hashlib
import io
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from el.base.userfiles import MAX_RECORD_BYTES, UserFileError, read_bytes

TABLE_COLUMNS = ("monitor", "criterion", "threshold", "perturbation", "auroc", "images", "miss_rate", "fp_rate",
                 "unsafe_landings", "g_star")
"""The columns of ``benchmark.csv`` the section reads (``assurance.analysis.benchmark.benchmark_table``)."""
MAX_MONITORS = 64
MAX_ROWS = 20_000


class BenchmarkFolderError(ValueError):
    """A benchmark folder the report cannot read: one line naming the file and the problem."""


def _read_csv(path: Path, what: str, **kw: Any) -> tuple[pd.DataFrame, str]:
    try:
        raw = read_bytes(path, what=what, max_bytes=MAX_RECORD_BYTES)
    except UserFileError as exc:
        raise BenchmarkFolderError(str(exc)) from None
    except OSError as exc:
        raise BenchmarkFolderError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    try:
        frame = pd.read_csv(io.BytesIO(raw), **kw)
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise BenchmarkFolderError(f"{path}: not a CSV {what} ({str(exc).splitlines()[0]})") from None
    if len(frame) > MAX_ROWS:
        raise BenchmarkFolderError(f"{path}: {len(frame)} rows, more than the {MAX_ROWS} a benchmark has")
    return frame, hashlib.sha256(raw).hexdigest()


def _numeric(frame: pd.DataFrame, columns: Any, path: Path) -> pd.DataFrame:
    """``columns`` of ``frame`` as floats; a text cell refuses the file (NaN stays: a criterion may find none)."""
    out = frame.copy()
    for c in columns:
        try:
            out[c] = pd.to_numeric(out[c], errors="raise").astype(float)
        except (ValueError, TypeError):
            raise BenchmarkFolderError(f"{path}: column {c!r} holds a value that is not a number") from None
    return out


def read_benchmark(folder: str | Path) -> dict[str, Any]:
    """The section's context from a ``uav-el benchmark --out`` folder; BenchmarkFolderError for a missing or
    malformed file (names it)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise BenchmarkFolderError(f"--benchmark {folder}: not a folder (give uav-el benchmark's --out)")
    tpath, bpath = folder / "benchmark.csv", folder / "blocks.csv"
    table, tsha = _read_csv(tpath, "benchmark table")
    missing = [c for c in TABLE_COLUMNS if c not in table.columns]
    if missing:
        raise BenchmarkFolderError(f"{tpath}: missing column(s) {', '.join(missing)} (written by uav-el benchmark)")
    table = _numeric(table, ("threshold", "auroc", "images", "miss_rate", "fp_rate", "unsafe_landings", "g_star"),
                     tpath)
    table["monitor"], table["criterion"] = table["monitor"].astype(str), table["criterion"].astype(str)
    table["perturbation"] = table["perturbation"].astype(str)
    blocks, bsha = _read_csv(bpath, "benchmark blocks table", index_col=0)
    blocks = _numeric(blocks, blocks.columns, bpath)
    if table["monitor"].nunique() > MAX_MONITORS or blocks.shape[1] > MAX_MONITORS:
        raise BenchmarkFolderError(f"{folder}: more than {MAX_MONITORS} monitors")
    return {"folder": str(folder), "files": [{"name": "benchmark.csv", "sha256": tsha},
                                             {"name": "blocks.csv", "sha256": bsha}],
            **_auroc_rows(table), "criteria": _criterion_rows(table), **_ranking(blocks)}


def _fmt(v: float, spec: str = ".3f") -> str:
    return "-" if v is None or not math.isfinite(float(v)) else format(float(v), spec)


def _auroc_rows(table: pd.DataFrame) -> dict[str, Any]:
    perts = sorted(table["perturbation"].unique())
    au = table.drop_duplicates(["monitor", "perturbation"]).pivot(index="monitor", columns="perturbation",
                                                                  values="auroc")
    rows = []
    for m, r in au.iterrows():
        vals = [float(r.get(p, math.nan)) for p in perts]
        finite = [v for v in vals if math.isfinite(v)]
        rows.append({"monitor": str(m), "cells": [_fmt(v) for v in vals],
                     "mean": _fmt(float(np.mean(finite))) if finite else "-"})
    rows.sort(key=lambda r: -float(r["mean"]) if r["mean"] != "-" else math.inf)
    return {"perturbations": perts, "auroc": rows}


def _criterion_rows(table: pd.DataFrame) -> list[dict[str, Any]]:
    out = []
    for c, sub in table.groupby("criterion", sort=False):
        rows = []
        for m, d in sub.groupby("monitor", sort=False):
            n = float(d["images"].sum())
            finite = d["g_star"].notna() & np.isfinite(d["g_star"])
            g = float(np.average(d.loc[finite, "g_star"], weights=d.loc[finite, "images"])) if (
                n and finite.any() and d.loc[finite, "images"].sum()) else math.nan
            rows.append({"monitor": m, "threshold": _fmt(d["threshold"].iloc[0], ".4g"),
                         "miss_rate": _fmt(d["miss_rate"].mean()), "fp_rate": _fmt(d["fp_rate"].mean()),
                         "unsafe": f"{_fmt(d['unsafe_landings'].sum(), '.0f')} / {int(n)}", "g_star": _fmt(g)})
        out.append({"criterion": str(c), "rows": rows})
    return out


def _ranking(blocks: pd.DataFrame) -> dict[str, Any]:
    """Friedman + Nemenyi recomputed from the blocks table, and the critical-difference diagram drawn here."""
    from assurance.analysis.ranking import cd_figure, rank_monitors  # deferred: matplotlib, off verify/land paths
    from assurance.evidence.plots import data_uri  # deferred: matplotlib, off verify/land paths

    try:
        r = rank_monitors(blocks)
    except ValueError as exc:
        return {"ranking": None, "why_not": str(exc)}
    fig = cd_figure(r, f"mean rank over {r.blocks} blocks (1 = best); Friedman p = {r.p_value:.3g}")
    return {"ranking": {"statistic": f"{r.statistic:.3f}", "p_value": f"{r.p_value:.4g}", "blocks": r.blocks,
                        "cd": f"{r.cd:.3f}", "alpha": f"{r.alpha:g}",
                        "ranks": [{"monitor": str(m), "rank": f"{v:.2f}"} for m, v in r.mean_ranks.items()],
                        "groups": ["{" + ", ".join(c) + "}" for c in r.cliques()]},
            "diagram": data_uri(fig), "why_not": ""}
