"""Threshold criteria by name, the Friedman / Nemenyi ranking, and the criterion recorded in a calibration card."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from assurance.analysis.criteria import CRITERIA, candidate_threshold, check_criterion, criterion_line
from assurance.analysis.ranking import cd_figure, nemenyi_cd, rank_monitors

SCORES = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
UNSAFE = np.array([False, False, True, False, True, True])


def test_criteria_by_hand():
    # reject iff score > t. t = 0.2: TP 3, FP 1, FN 0 -> F1 6/7, TPR 1, TNR 2/3 (G-mean 0.816): the best of both
    # t = 0.4: TP 2, FP 0 -> F1 0.8, G-mean 0.816 too; the smaller (more cautious) threshold wins the tie
    t, note = candidate_threshold("f1", SCORES, UNSAFE)
    assert t == pytest.approx(0.2) and "0.857" in note
    t, _ = candidate_threshold("g-mean", SCORES, UNSAFE)
    assert t == pytest.approx(0.2)
    t, note = candidate_threshold("tnr-at-recall", SCORES, UNSAFE, recall=0.6)  # 2 of 3 unsafe suffice: t = 0.4
    assert t == pytest.approx(0.4) and "TNR 1.000" in note
    t, _ = candidate_threshold("tnr-at-recall", SCORES, UNSAFE, recall=1.0)  # every unsafe one: t just below 0.3
    assert t == pytest.approx(0.2)


def test_guarantee_is_the_calibration_and_system_criteria_are_refused_on_candidates():
    from assurance.fitting.calibration import calibrate_threshold

    rng = np.random.default_rng(0)
    s, y = rng.random(400), rng.random(400) < 0.5
    t, note = candidate_threshold("guarantee", s, y, miss_rate=0.1, confidence=0.9)
    assert t == calibrate_threshold(s[y], 0.1, 0.9)["threshold"] and "0.1" in note
    with pytest.raises(ValueError, match="sweep"):
        candidate_threshold("fewest-unsafe", s, y)
    with pytest.raises(ValueError, match="known"):
        check_criterion("auc")
    assert set(CRITERIA) == {"fewest-unsafe", "g-star", "guarantee", "f1", "g-mean", "tnr-at-recall"}
    assert "0.9" in criterion_line("tnr-at-recall", 0.9)


def test_nemenyi_cd_is_demsars_and_friedman_is_scipys():
    from scipy.stats import friedmanchisquare

    assert nemenyi_cd(4, 10) == pytest.approx(2.569 * math.sqrt(4 * 5 / 60), abs=1e-3)  # Demsar 2006, q_0.05(4)
    assert nemenyi_cd(3, 6) == pytest.approx(2.343 * math.sqrt(3 * 4 / 36), abs=1e-3)
    m = pd.DataFrame({"a": [0.9, 0.8, 0.85, 0.95], "b": [0.7, 0.6, 0.65, 0.9], "c": [0.5, 0.7, 0.6, 0.4]})
    r = rank_monitors(m)
    assert list(r.mean_ranks.index) == ["a", "b", "c"] and r.mean_ranks["a"] == 1.0
    assert r.statistic == pytest.approx(friedmanchisquare(m["a"], m["b"], m["c"]).statistic)
    assert r.blocks == 4 and r.different("a", "c") == (r.mean_ranks["c"] - 1.0 > r.cd)


def test_ranking_needs_three_monitors_and_two_complete_blocks_and_draws_a_diagram():
    with pytest.raises(ValueError, match="3 monitors"):
        rank_monitors(pd.DataFrame({"a": [1, 2], "b": [2, 1]}))
    with pytest.raises(ValueError, match="2 blocks"):
        rank_monitors(pd.DataFrame({"a": [1, np.nan], "b": [2, 1], "c": [0, 0]}))
    r = rank_monitors(pd.DataFrame({"a": [1.0, 1.0], "b": [1.0, 1.0], "c": [1.0, 1.0]}))
    assert r.p_value == 1.0 and r.cliques() == [("a", "b", "c")]
    assert cd_figure(r, "t").axes


def test_a_card_records_its_criterion_and_claims_no_guarantee_for_a_benchmark_one():
    from assurance.fitting.calibration import ThresholdRule, calibration_body

    kw = {"monitor": "msp", "split": {}, "weights": {}}
    rng = np.random.default_rng(1)
    s, y = rng.random(200), rng.random(200) < 0.5
    b = calibration_body(s, y, **kw, rule=ThresholdRule(miss_rate=0.1, confidence=0.9))
    assert b["criterion"]["name"] == "guarantee" and b["bound"] <= 0.1
    f = calibration_body(s, y, **kw, rule=ThresholdRule(miss_rate=0.1, confidence=0.9, criterion="f1"))
    assert f["criterion"]["name"] == "f1" and f["bound"] is None and f["guarantee"].startswith("none")
    assert f["spec"] == f"msp:threshold={f['threshold']!r}"
    assert f["counts"]["unsafe"] + f["counts"]["safe"] == 200


def test_benchmark_help_names_the_criteria_and_the_friedman_nemenyi_comparison(capsys):
    from assurance import cli

    with pytest.raises(SystemExit):
        cli.main(["benchmark", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(c in text for c in CRITERIA) and "Friedman" in text and "Nemenyi" in text


def test_sweep_and_calibrate_take_the_criterion_by_name(capsys):
    from assurance import cli

    for command in ("sweep", "calibrate"):
        with pytest.raises(SystemExit):
            cli.main([command, "--help"])
        text = capsys.readouterr().out
        assert "--criterion" in text and "tnr-at-recall" in text


def test_el_r16_on_a_card_without_a_guarantee_is_insufficient_not_a_crash():
    """A card a benchmark criterion chose carries no miss rate: EL-R16 says so instead of judging None."""
    from assurance.fitting.calibration import ThresholdRule, calibration_body
    from assurance.requirements.calibration_check import check_calibrated_miss_rate
    from el.monitors.calibration import CalibrationCard

    rng = np.random.default_rng(2)
    s, y = rng.random(100), rng.random(100) < 0.5
    body = calibration_body(s, y, monitor="msp", rule=ThresholdRule(miss_rate=0.1, confidence=0.9, criterion="f1"),
                            split={}, weights={})
    card = CalibrationCard("card.json", "0" * 64, body)
    ev = check_calibrated_miss_rate(pd.DataFrame({"perturbation": ["none"]}), card)
    assert ev.status == "insufficient" and "'f1'" in ev.summary and "--criterion guarantee" in ev.summary
