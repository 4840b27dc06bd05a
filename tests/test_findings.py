"""The paper's findings asked of a results table: counts, deltas, cost ratios and ties."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from assurance.analysis.findings import findings, findings_markdown
from assurance.analysis.reference import load_reference

MONITORS = ("lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.9")


def table(rows: dict[tuple[str, str], dict[str, float]]) -> pd.DataFrame:
    base = {"severity": 3, "g_cm": 0.3, "g_cm_lo95": 0.1, "mcc": 0.5, "recall": 0.8, "fp_rate": 0.2,
            "g_star": 0.4, "overhead_s": 1.0}
    return pd.DataFrame([{"perturbation": p, "monitor": m, **base, **v} for (p, m), v in rows.items()])


def by_key(items):
    return {f.key: f for f in items}


def test_cm_vs_default_counts_perturbations_with_a_positive_gain():
    df = table({("none", m): {} for m in MONITORS} | {("fog", m): {"g_cm": -0.1, "g_cm_lo95": -0.3} for m in MONITORS})
    f = by_key(findings(df))["cm_vs_default"]
    assert list(f.table["perturbation"]) == ["none", "fog"]
    assert "under 1 of 2 perturbations (1 with the 95% interval above 0)" in f.verdict
    assert "paper: 0 of 0" in f.verdict  # no reference given


def test_ch_and_mcd_effects_are_differences_from_lhd_alone():
    df = table({("none", "lhd"): {},
                ("none", "lhd+ch:tau=0.25"): {"recall": 0.9, "fp_rate": 0.5},
                ("none", "lhd+mcd:n=10,rho=0.9"): {"mcc": 0.45, "g_star": 0.38, "overhead_s": 4.0}})
    f = by_key(findings(df))
    ch = f["ch"].table.iloc[0]
    assert ch["d_recall"] == pytest.approx(0.1) and ch["d_fp_rate"] == pytest.approx(0.3)
    assert math.isnan(ch["d_recall_paper"])
    mcd = f["mcd"].table.iloc[0]
    assert mcd["d_mcc_mean"] == pytest.approx(-0.05) and mcd["d_g_star_mean"] == pytest.approx(-0.02)
    assert mcd["cost_ratio"] == pytest.approx(4.0)
    assert "overhead x4.0" in f["mcd"].verdict


def test_best_configuration_prefers_the_cheaper_of_equal_g_star():
    df = table({("none", "lhd"): {"g_star": 0.4}, ("none", "lhd+ch:tau=0.25"): {"g_star": 0.4 + 1e-12},
                ("none", "lhd+mcd:n=10,rho=0.9"): {"g_star": 0.3}})
    best = by_key(findings(df))["best"].table.iloc[0]
    assert best["best"] == "lhd"
    df.loc[df["monitor"] == "lhd+ch:tau=0.25", "g_star"] = 0.5
    assert by_key(findings(df))["best"].table.iloc[0]["best"] == "lhd+ch:tau=0.25"


def test_the_published_table_answers_the_papers_own_questions():
    ref = load_reference()
    f = by_key(findings(ref, ref))
    assert "G_CM > 0 under 6 of 6 perturbations" in f["cm_vs_default"].verdict
    assert "same kind" in f["best"].verdict and "under 6 of 6" in f["best"].verdict
    # The paper: CH raises recall and FP rate (both taus, every perturbation).
    ch = f["ch"].table
    assert len(ch) == 12 and (ch["d_recall"] >= 0).all() and (ch["d_fp_rate"] > 0).all()
    # ... and MC dropout costs over ten times LHD's overhead.
    assert (f["mcd"].table["cost_ratio"] > 10).all()
    md = findings_markdown(list(f.values()))
    assert md.count("**") == 8 and "| perturbation |" in md


def test_empty_table_is_an_error():
    with pytest.raises(ValueError, match="empty"):
        findings(pd.DataFrame(columns=["perturbation", "monitor"]))
