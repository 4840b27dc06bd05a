"""The monitor figures of Guerin et al. (ISSRE 2022, "Unifying evaluation of machine learning safety monitors"):
safety gain TP/N, residual hazard FN/N and availability cost FP/N over the N candidates a monitor judged, per
configuration and perturbation, with 95% bootstrap intervals over images (the harness's one bootstrap), under
both labellings:
"model error" (a positive is a truly unsafe candidate: the ML output was wrong) and "runtime threat" (a positive
is a candidate of a perturbed image, whatever the model made of it)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from assurance.analysis.confusion import confusion
from assurance.analysis.intervals import image_bootstrap
from assurance.analysis.table import _scenario_order, image_readouts
from assurance.campaign import readouts

LABELLINGS = ("model error", "runtime threat")
FIGURES = (("safety_gain", 0), ("residual_hazard", 3), ("availability_cost", 1))
"""Figure name and its column in a [tp, fp, tn, fn] count row."""
COLUMNS = ("perturbation", "severity", "monitor", "labelling", "images", "n", "tp", "fp", "tn", "fn",
           *(f"{name}{s}" for name, _ in FIGURES for s in ("", "_lo95", "_hi95")))


def _row(scen: tuple[str, int, str], labelling: str, counts: np.ndarray, n_boot: int, seed: int) -> dict[str, Any]:
    """One table row from per-image count rows ``counts`` (images x [tp, fp, tn, fn]), with the harness's one
    bootstrap over images (``image_bootstrap``: the same resamples for the same seed and image count)."""
    pert, sev, mon = scen
    total = counts.sum(axis=0)
    n = int(total.sum())
    row: dict[str, Any] = {"perturbation": pert, "severity": sev, "monitor": mon, "labelling": labelling,
                           "images": len(counts), "n": n, **dict(zip(("tp", "fp", "tn", "fn"), map(int, total),
                                                                   strict=True))}
    for name, col in FIGURES:
        row[name] = total[col] / n if n else math.nan

        def ratio(idx: np.ndarray, col: int = col) -> np.ndarray:
            boot = counts[idx].sum(axis=-2)
            with np.errstate(all="ignore"):
                return np.where(boot.sum(axis=-1) > 0, boot[..., col] / boot.sum(axis=-1), np.nan)

        row[f"{name}_lo95"], row[f"{name}_hi95"] = (image_bootstrap(len(counts), ratio, n_boot=n_boot, seed=seed)
                                                    if n else (math.nan, math.nan))
    return row


def issre_table(run: str | Path, *, n_boot: int = 2000, seed: int = 0) -> pd.DataFrame:
    """One row per (perturbation, severity, monitor, labelling), columns ``COLUMNS``, in the campaign's order."""
    cfg = readouts.read_manifest(run)["config"]
    order = [(p, s, m) for p, s in _scenario_order(cfg) for m in cfg["monitors"]]
    images = readouts.load_table(run, "images")
    candidates = readouts.load_table(run, "candidates")
    return issre_frame(images, candidates, n_boot=n_boot, seed=seed, order=order)


def issre_frame(images: pd.DataFrame, candidates: pd.DataFrame, *, n_boot: int = 2000, seed: int = 0,
                order: list[tuple[str, int, str]] | None = None) -> pd.DataFrame:
    """``issre_table`` from the run's images and candidates tables; rows in ``order`` (scenarios) when given."""
    rows = []
    per_scen = image_readouts(images, candidates)
    for scen in order or list(per_scen):
        recs = per_scen.get(scen)
        if not recs:
            continue
        recs = sorted(recs, key=lambda r: r.image_id)  # as the results table: resampling independent of order
        model = np.array([r.counts.as_array() for r in recs], dtype=np.int64).reshape(len(recs), 4)
        threat_positive = scen[0] != "none"
        threat = np.array([confusion(np.full(r.counts.total, threat_positive), r.rejected).as_array()
                           for r in recs], dtype=np.int64).reshape(len(recs), 4)
        rows.append(_row(scen, LABELLINGS[0], model, n_boot, seed))
        rows.append(_row(scen, LABELLINGS[1], threat, n_boot, seed))
    return pd.DataFrame(rows, columns=list(COLUMNS))

