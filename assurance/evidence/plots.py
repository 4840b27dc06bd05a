"""Plots of the evidence report (matplotlib, Agg canvas, no pyplot state): PNG data URIs.

- ``gains_figure``: safety gains G_CM / G_RM / G* per perturbation and monitor configuration, with
  95% bootstrap intervals (bars for one severity, lines over severity when a campaign has several).
- ``monitor_metrics_figure``: precision, recall and FP rate per perturbation and monitor (dot plot).
- ``overhead_figure``: monitoring overhead per image and monitor configuration (mean, 95th percentile).
"""

from __future__ import annotations

import base64
import io
import math
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from assurance.analysis.scores import auroc, roc_curve

WIDTH_IN = 6.9  # the A4 text width (about 175 mm)
DPI = 130
COLOURS = {"g_cm": "#9aa5b1", "g_rm": "#e8a33d", "g_star": "#2a7ab9",
           "precision": "#2a7ab9", "recall": "#2e9e5b", "fp_rate": "#d64545", "deployed": "#fff4cc"}


def data_uri(fig: Figure) -> str:
    """The figure as a PNG data URI (the report embeds every image)."""
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _v(x: Any) -> float:
    try:
        f = float(x)
    except (TypeError, ValueError):
        return math.nan
    return f


def _err(rows: Any, name: str) -> np.ndarray:
    """(2, n) error-bar lengths from the ``_lo95`` / ``_hi95`` columns (0 where undefined)."""
    v = rows[name].to_numpy(float)
    lo = rows[f"{name}_lo95"].to_numpy(float)
    hi = rows[f"{name}_hi95"].to_numpy(float)
    err = np.vstack([v - lo, hi - v])
    return np.where(np.isfinite(err), np.maximum(err, 0), 0)


def _grid(n: int, ncols: int = 2) -> tuple[int, int]:
    """(rows, columns) of a panel grid for n panels."""
    ncols = min(ncols, n)
    return int(math.ceil(n / ncols)), ncols


def _perturbations(table: Any) -> list[str]:
    return list(dict.fromkeys(table["perturbation"]))


def gains_figure(table: Any, deployed: str) -> str:
    """Safety gains per perturbation (one panel each) and monitor configuration."""
    perts = _perturbations(table)
    monitors = list(dict.fromkeys(table["monitor"]))
    multi = table.groupby("perturbation")["severity"].nunique().max() > 1
    nrows, ncols = _grid(len(perts), 3 if len(monitors) > 6 else 2)
    per_row = 0.9 + (min(0.22, 6.0 / max(1, len(monitors)) / 2.2) * len(monitors) if not multi else 1.3)
    fig = Figure(figsize=(WIDTH_IN, per_row * nrows + 0.5))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    lo_all = np.nanmin([_v(x) for x in table[["g_cm", "g_rm_lo95", "g_star_lo95"]].to_numpy().ravel()] + [0.0])
    hi_all = np.nanmax([_v(x) for x in table[["g_cm", "g_rm_hi95", "g_star_hi95"]].to_numpy().ravel()] + [0.0])
    pad = 0.05 * max(hi_all - lo_all, 0.1)
    for k, pert in enumerate(perts):
        ax = axes[k // ncols][k % ncols]
        rows = table[table["perturbation"] == pert]
        if multi:
            for mon in monitors:
                r = rows[rows["monitor"] == mon].sort_values("severity")
                sev = r["severity"].to_numpy(int)
                ax.plot(sev, r["g_star"].to_numpy(float), marker="o", ms=3, lw=1.6 if mon == deployed else 0.9,
                        label=mon)
                ax.fill_between(sev, r["g_star_lo95"].to_numpy(float), r["g_star_hi95"].to_numpy(float), alpha=0.12)
            ax.set_xlabel("severity", fontsize=7)
            ax.set_ylabel("G*", fontsize=7)
            ax.axhline(0, color="k", lw=0.6)
            ax.set_ylim(lo_all - pad, hi_all + pad)
        else:
            y = np.arange(len(rows))
            names = list(rows["monitor"])
            for j, name in enumerate(names):
                if name == deployed:
                    ax.axhspan(j - 0.5, j + 0.5, color=COLOURS["deployed"], zorder=0)
            ax.barh(y - 0.18, rows["g_rm"].to_numpy(float), height=0.34, color=COLOURS["g_rm"],
                    xerr=_err(rows, "g_rm"), error_kw={"lw": 0.7}, label="G_RM (monitor)")
            ax.barh(y + 0.18, rows["g_star"].to_numpy(float), height=0.34, color=COLOURS["g_star"],
                    xerr=_err(rows, "g_star"), error_kw={"lw": 0.7}, label="G* (CM + monitor)")
            g_cm = _v(rows["g_cm"].iloc[0]) if len(rows) else math.nan
            if math.isfinite(g_cm):
                ax.axvline(g_cm, color=COLOURS["g_cm"], lw=1.5, ls="--", label="G_CM (core model)")
            ax.axvline(0, color="k", lw=0.6)
            ax.set_yticks(y)
            ax.set_yticklabels(names if k % ncols == 0 else [], fontsize=6)
            ax.set_ylim(len(rows) - 0.5, -0.5)
            ax.set_xlim(lo_all - pad, hi_all + pad)
        ax.xaxis.set_major_locator(MaxNLocator(5))
        sev_txt = ", ".join(f"s{s}" for s in sorted(set(rows["severity"])))
        ax.set_title(f"{pert} ({sev_txt})", fontsize=8)
        ax.tick_params(axis="x", labelsize=6)
        ax.grid(axis="x" if not multi else "y", lw=0.3, alpha=0.6)
    for k in range(len(perts), nrows * ncols):
        axes[k // ncols][k % ncols].set_visible(False)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(4, len(labels)), fontsize=7, frameon=False)
    fig.suptitle("Safety gain (hazard reduction, higher is safer) with 95% bootstrap intervals; "
                 f"shaded: deployed monitor ({deployed})", fontsize=8)
    fig.tight_layout(rect=(0, 0.05 if not multi else 0.1, 1, 0.97))
    return data_uri(fig)


def monitor_metrics_figure(table: Any, deployed: str) -> str:
    """Precision, recall and FP rate (pooled over candidates, 95% bootstrap intervals) per scenario."""
    scen = list(dict.fromkeys(zip(table["perturbation"], table["severity"], strict=True)))
    if len(scen) > 8:  # many severities: the severity closest to 3 of each perturbation
        best: dict[str, tuple[str, int]] = {}
        for p, s in scen:
            if p not in best or abs(s - 3) < abs(best[p][1] - 3):
                best[p] = (p, s)
        scen = list(best.values())
    monitors = list(dict.fromkeys(table["monitor"]))
    nrows, ncols = _grid(len(scen), 3 if len(monitors) > 6 else 2)
    fig = Figure(figsize=(WIDTH_IN, (0.8 + min(0.2, 2.7 / max(1, len(monitors))) * len(monitors)) * nrows + 0.5))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for k, (p, s) in enumerate(scen):
        ax = axes[k // ncols][k % ncols]
        rows = table[(table["perturbation"] == p) & (table["severity"] == s)]
        y = np.arange(len(rows))
        for j, name in enumerate(rows["monitor"]):
            if name == deployed:
                ax.axhspan(j - 0.5, j + 0.5, color=COLOURS["deployed"], zorder=0)
        for off, (name, marker) in zip((-0.22, 0.0, 0.22), (("precision", "o"), ("recall", "s"), ("fp_rate", "^")),
                                       strict=True):
            ax.errorbar(rows[name].to_numpy(float), y + off, xerr=_err(rows, name), fmt=marker, ms=3.5,
                        color=COLOURS[name], lw=0.7, label={"fp_rate": "FP rate"}.get(name, name.capitalize()))
        ax.set_yticks(y)
        ax.set_yticklabels(list(rows["monitor"]) if k % ncols == 0 else [], fontsize=6)
        ax.set_ylim(len(rows) - 0.5, -0.5)
        ax.set_xlim(-0.03, 1.03)
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_title(f"{p} (s{s})", fontsize=8)
        ax.tick_params(axis="x", labelsize=6)
        ax.grid(axis="x", lw=0.3, alpha=0.6)
    for k in range(len(scen), nrows * ncols):
        axes[k // ncols][k % ncols].set_visible(False)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.suptitle("Runtime monitor as a classifier of unsafe candidates (missing marker: undefined ratio)",
                 fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return data_uri(fig)


def overhead_figure(images: Any, monitors: list[str], budget_s: float, deployed: str) -> str:
    """Monitoring overhead per image (the decision loop's walk) per monitor configuration."""
    ok = images[images["fault"].fillna("") == ""]
    fig = Figure(figsize=(WIDTH_IN, 0.9 + 0.25 * len(monitors)))
    ax = fig.subplots()
    y = np.arange(len(monitors))
    means, p95s, maxs = [], [], []
    for mon in monitors:
        o = ok.loc[ok["monitor"] == mon, "overhead_s"].to_numpy(float)
        means.append(o.mean() if o.size else math.nan)
        p95s.append(np.percentile(o, 95) if o.size else math.nan)
        maxs.append(o.max() if o.size else math.nan)
    for j, name in enumerate(monitors):
        if name == deployed:
            ax.axhspan(j - 0.5, j + 0.5, color=COLOURS["deployed"], zorder=0)
    ax.barh(y, means, height=0.5, color=COLOURS["g_star"], label="mean per image")
    ax.plot(p95s, y, "k|", ms=10, mew=1.5, label="95th percentile")
    ax.plot(maxs, y, "x", color=COLOURS["fp_rate"], ms=5, label="max")
    ax.set_yticks(y)
    ax.set_yticklabels(monitors, fontsize=6)
    ax.set_ylim(len(monitors) - 0.5, -0.5)
    ax.set_xlabel("monitoring time per decision (s), on the campaign's machine", fontsize=7)
    ax.tick_params(axis="x", labelsize=6)
    ax.grid(axis="x", lw=0.3, alpha=0.6)
    top = np.nanmax(maxs + [0.0])
    note = f"time budget of the whole decision: {budget_s:g} s"
    if top >= 0.3 * budget_s:
        ax.axvline(budget_s, color=COLOURS["fp_rate"], ls="--", lw=1)
    ax.set_title(f"Runtime-monitor overhead ({note})", fontsize=8)
    ax.legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    return data_uri(fig)


def roc_figure(candidates: Any, monitors: list[str], deployed: str, perturbation: str = "none") -> str | None:
    """ROC curves of the monitors' scores (unsafe candidates as positives) under one perturbation, with each
    configuration's operating point (its threshold) marked; None when the run holds no scores."""
    if candidates is None or len(candidates) == 0 or "score" not in candidates.columns:
        return None
    sub = candidates[candidates["perturbation"] == perturbation]
    if sub.empty or sub["score"].isna().all():
        return None
    fig = Figure(figsize=(WIDTH_IN * 0.62, WIDTH_IN * 0.55))
    ax = fig.subplots()
    for mon in monitors:
        g = sub[sub["monitor"] == mon]
        if g.empty or g["score"].isna().all():
            continue
        y = g["true_unsafe"].to_numpy(bool)
        fpr, tpr, _ = roc_curve(g["score"], y)
        a = auroc(g["score"], y)
        lw = 1.8 if mon == deployed else 0.9
        (line,) = ax.plot(fpr, tpr, lw=lw, label=f"{mon} (AUROC {a:.3f})" if math.isfinite(a) else mon)
        rejected = ~g["accepted"].to_numpy(bool)
        op_tpr = rejected[y].mean() if y.any() else math.nan
        op_fpr = rejected[~y].mean() if (~y).any() else math.nan
        ax.plot([op_fpr], [op_tpr], "o", ms=5 if mon == deployed else 3.5, color=line.get_color(), mec="k", mew=0.5)
    ax.plot([0, 1], [0, 1], color="#999999", lw=0.6, ls=":")
    ax.set_xlim(-0.01, 1.01)
    ax.set_ylim(-0.01, 1.01)
    ax.set_xlabel("false-positive rate (safe candidates rejected)", fontsize=7)
    ax.set_ylabel("recall (unsafe candidates rejected)", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.grid(lw=0.3, alpha=0.6)
    ax.legend(fontsize=5.5, loc="lower right")
    ax.set_title(f"ROC of the monitor scores ({perturbation}); dot: the configuration's threshold", fontsize=8)
    fig.tight_layout()
    return data_uri(fig)
