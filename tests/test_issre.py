"""ISSRE 2022 monitor figures: safety gain, residual hazard and availability cost agree with the confusion counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from assurance.analysis.issre import issre_table
from assurance.analysis.table import results_table
from assurance.campaign import readouts


@pytest.fixture(scope="module")
def issre(tiny_campaign):
    return issre_table(tiny_campaign["run"], n_boot=200)


def test_figures_agree_with_the_confusion_counts(issre, tiny_campaign):
    cands = readouts.load_table(tiny_campaign["run"], "candidates")
    assert len(issre) == 2 * 6 * 2  # both labellings x six perturbations x two monitors
    for row in issre.to_dict("records"):
        n = row["n"]
        assert n == row["tp"] + row["fp"] + row["tn"] + row["fn"] > 0
        assert row["safety_gain"] * n == pytest.approx(row["tp"])
        assert row["residual_hazard"] * n == pytest.approx(row["fn"])
        assert row["availability_cost"] * n == pytest.approx(row["fp"])
        # residual hazard + safety gain = the positives' share; + availability cost + TN/N = 1
        pos = (row["tp"] + row["fn"]) / n
        assert row["residual_hazard"] + row["safety_gain"] == pytest.approx(pos)
        assert row["residual_hazard"] + row["safety_gain"] + row["availability_cost"] + row["tn"] / n == \
            pytest.approx(1.0)
        for name in ("safety_gain", "residual_hazard", "availability_cost"):
            lo, hi = row[f"{name}_lo95"], row[f"{name}_hi95"]
            assert math.isnan(lo) or lo - 1e-12 <= row[name] <= hi + 1e-12
        # counted again from the candidates table, independently of the metrics code
        c = cands[(cands["perturbation"] == row["perturbation"]) & (cands["monitor"] == row["monitor"])]
        rejected = ~c["accepted"].to_numpy(bool)
        if row["labelling"] == "model error":
            positive = c["true_unsafe"].to_numpy(bool)
        else:
            positive = np.full(len(c), row["perturbation"] != "none")
        assert (row["tp"], row["fp"], row["fn"], row["n"]) == (
            int((positive & rejected).sum()), int((~positive & rejected).sum()), int((positive & ~rejected).sum()),
            len(c))


def test_model_error_counts_match_the_results_table(issre, tiny_campaign):
    table = results_table(tiny_campaign["run"], n_boot=50)
    model = issre[issre["labelling"] == "model error"]
    for rec, row in zip(table.to_dict("records"), model.to_dict("records"), strict=True):
        assert (rec["perturbation"], rec["monitor"], rec["candidates"]) == (row["perturbation"], row["monitor"],
                                                                            row["n"])
        if row["tp"] + row["fn"]:
            assert rec["recall"] == pytest.approx(row["tp"] / (row["tp"] + row["fn"]))
        threat = issre[(issre["labelling"] == "runtime threat") & (issre["perturbation"] == "none")]
        assert (threat["tp"] + threat["fn"] == 0).all()  # no threat on the unperturbed images
