"""The paper's published results, in the project's vocabulary.

Source: J. Guerin, K. Delmas and J. Guiochet, "Evaluation of Runtime Monitoring for UAV Emergency
Landing", ICRA 2022: its complete per-configuration results (6 perturbations x 21 monitor
configurations, 70 UAVid validation images each), shipped verbatim as
``assurance/data/guerin2022_results.csv``. ``load_reference()`` renames the columns to those of the
project's results table (``assurance.analysis.metrics.RESULT_COLUMNS``), the perturbations to
``assurance.perturbations`` names and the monitor configurations to spec names (``"lhd"``,
``"lhd+ch:tau=0.25"``, ``"lhd+mcd:n=10,rho=0.5"``, ``"lhd+ch+mcd:tau=0.125,n=30,rho=0.9"``), so a
campaign's table and the paper's can be joined on ``(perturbation, monitor)``.

Every published value is kept as published. One row has a known typo: None / N_MCD 30 / tau 0.25
/ rho 0.75 gives precision 0.964 where its F1 (0.790) and recall (0.916) imply 0.694; such rows
are found by a consistency check, not by a hard-coded key, and named in the ``flag`` column.

Examples
--------
>>> ref = load_reference()
>>> len(ref), ref.loc[(ref.perturbation == "fog") & (ref.monitor == "lhd"), "g_star"].item()
(126, 0.426)
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from assurance.analysis.metrics import RESULT_COLUMNS
from assurance.perturbations import TRAITS

__all__ = [
    "PERTURBATION_NAMES",
    "REFERENCE_CSV",
    "REFERENCE_IMAGES",
    "REFERENCE_SEVERITY",
    "implied_precision",
    "load_reference",
    "monitor_spec_name",
]

REFERENCE_CSV = "guerin2022_results.csv"
REFERENCE_IMAGES = 70  # UAVid validation images per scenario (paper, Table I caption)
REFERENCE_SEVERITY = 3  # the paper's settings are our severity 3 (docs/architecture.md section 4.1)

PERTURBATION_NAMES: dict[str, str] = {
    "None": "none",
    "Brightness": "brightness",
    "Fog": "fog",
    "Motion Blur": "motion_blur",
    "Shifted pixels": "shifted_pixels",
    "Pixel trap": "pixel_trap",
}
"""Published perturbation name -> ``assurance.perturbations`` name."""

_COLUMNS = {  # published column -> project column
    "Monitor MCC": "mcc",
    "Monitor precision": "precision",
    "Monitor recall": "recall",
    "Monitor F1 score": "f1",
    "Monitor FP rate": "fp_rate",
    "Monitor FN rate": "fn_rate",
    "Core model SG": "g_cm",
    "Monitor SG": "g_rm",
    "Full SG": "g_star",
    "Average overhead monitor": "overhead_s",
}

_ORDER = (
    *RESULT_COLUMNS[: RESULT_COLUMNS.index("unsafe_landing_rate")],  # the results table's figures, same order
    "fn_rate",
    "kind",
    "tau",
    "n_mcd",
    "rho",
    "unsafe_share",
    "flag",
    "source_perturbation",
)

# Published figures have 3 decimals: precision implied by F1 and recall is good to about 0.003
# (worst gap in the table: 0.002); a larger one is a transcription error.
PRECISION_TOLERANCE = 0.005


def monitor_spec_name(tau: float | None = None, n_mcd: int | None = None, rho: float | None = None) -> str:
    """Spec name of a configuration: LHD always, CH when ``tau`` is set, MCD when ``n_mcd``/``rho`` are.

    >>> monitor_spec_name(), monitor_spec_name(tau=0.125, n_mcd=30, rho=0.9)
    ('lhd', 'lhd+ch+mcd:tau=0.125,n=30,rho=0.9')
    """
    if (n_mcd is None) != (rho is None):
        raise ValueError(f"MCD needs both n_mcd and rho, got n_mcd={n_mcd!r}, rho={rho!r}")
    kind = "lhd" + ("+ch" if tau is not None else "") + ("+mcd" if n_mcd is not None else "")
    params = []
    if tau is not None:
        params.append(f"tau={float(tau)!r}")
    if n_mcd is not None:
        params += [f"n={int(n_mcd)}", f"rho={float(rho)!r}"]
    return kind + (":" + ",".join(params) if params else "")


def implied_precision(f1: float | np.ndarray, recall: float | np.ndarray) -> float | np.ndarray:
    """Precision implied by F1 and recall, ``F1 R / (2 R - F1)`` (NaN where undefined)."""
    f1 = np.asarray(f1, dtype=np.float64)
    recall = np.asarray(recall, dtype=np.float64)
    den = 2 * recall - f1
    out = np.full(np.broadcast(f1, den).shape, np.nan)
    np.divide(f1 * recall, den, out=out, where=den > 0)
    return out if out.ndim else float(out)


def _unused(value: float) -> bool:
    return value == -1


def load_reference(path: str | Path | None = None) -> pd.DataFrame:
    """The paper's 126 published rows as a DataFrame in the project's vocabulary.

    Parameters
    ----------
    path : str or Path, optional
        Another copy of the published CSV (same columns; ``#`` lines are comments). Default: the
        packaged ``assurance/data/guerin2022_results.csv``.

    Returns
    -------
    DataFrame, one row per (perturbation, monitor), in the published order, with columns

    - ``perturbation`` (``assurance.perturbations`` name), ``severity`` (Int64: 3 for the five
      perturbations, whose published settings are our severity 3; <NA> for ``none``),
      ``monitor`` (spec name), ``images`` (70), ``candidates`` (Int64 <NA>: not published);
    - the published figures under the results-table names: ``g_cm, mcc, f1, precision, recall,
      fp_rate, g_rm, overhead_s`` (seconds per image), ``g_star``, and ``fn_rate``;
    - ``kind`` (``lhd``, ``lhd+ch``, ``lhd+mcd``, ``lhd+ch+mcd``), ``tau``, ``n_mcd`` (Int64),
      ``rho`` (NaN / <NA> when not used);
    - ``unsafe_share``: share of truly unsafe candidates implied by precision, recall and FP
      rate, ``P F / (R (1 - P) + P F)`` (NaN on a flagged row);
    - ``flag``: empty, or why a published value is inconsistent with the others;
    - ``source_perturbation``: the published perturbation name.
    """
    # keep_default_na=False: the perturbation "None" is a name, not a missing value
    options = {"comment": "#", "keep_default_na": False}
    if path is None:
        with resources.as_file(resources.files("assurance") / "data" / REFERENCE_CSV) as p:
            raw = pd.read_csv(p, **options)
    else:
        raw = pd.read_csv(path, **options)
    missing = {"Perturbation", "Samples MCD", "Threshold", "Dropout rate", *_COLUMNS} - set(raw.columns)
    if missing:
        raise ValueError(f"reference CSV lacks columns {sorted(missing)}")
    unknown = sorted(set(raw["Perturbation"]) - set(PERTURBATION_NAMES))
    if unknown:
        raise ValueError(f"reference CSV has unknown perturbations {unknown}")

    df = raw.rename(columns=_COLUMNS)
    tau = [None if _unused(t) else float(t) for t in raw["Threshold"]]
    n_mcd = [None if _unused(n) else int(n) for n in raw["Samples MCD"]]
    rho = [None if _unused(r) else float(r) for r in raw["Dropout rate"]]
    df["source_perturbation"] = raw["Perturbation"]
    df["perturbation"] = raw["Perturbation"].map(PERTURBATION_NAMES)
    df["severity"] = pd.array(
        [REFERENCE_SEVERITY if TRAITS[p].graded else pd.NA for p in df["perturbation"]], dtype="Int64"
    )
    df["monitor"] = [monitor_spec_name(t, n, r) for t, n, r in zip(tau, n_mcd, rho, strict=True)]
    df["kind"] = [name.partition(":")[0] for name in df["monitor"]]
    df["tau"] = np.array([math.nan if t is None else t for t in tau], dtype=np.float64)
    df["n_mcd"] = pd.array([pd.NA if n is None else n for n in n_mcd], dtype="Int64")
    df["rho"] = np.array([math.nan if r is None else r for r in rho], dtype=np.float64)
    df["images"] = REFERENCE_IMAGES
    df["candidates"] = pd.array([pd.NA] * len(df), dtype="Int64")

    implied = implied_precision(df["f1"].to_numpy(), df["recall"].to_numpy())
    bad = np.abs(df["precision"].to_numpy() - implied) > PRECISION_TOLERANCE
    df["flag"] = [
        f"precision {p:.3f} inconsistent with F1 and recall (imply {q:.3f}); published value kept"
        if b
        else ""
        for p, q, b in zip(df["precision"], implied, bad, strict=True)
    ]
    p, r, f = (df[c].to_numpy(dtype=np.float64) for c in ("precision", "recall", "fp_rate"))
    share = p * f / (r * (1 - p) + p * f)
    df["unsafe_share"] = np.where(bad, np.nan, share)

    if df.duplicated(["perturbation", "monitor"]).any():
        raise ValueError("reference CSV has duplicate (perturbation, monitor configuration) rows")
    return df.loc[:, list(_ORDER)].reset_index(drop=True)
