"""Threshold sweeps replay the decision loop exactly from a campaign's scores."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from assurance.analysis.sweep import SweepError, choose, replay, sweep
from assurance.analysis.sweep_report import sweep_run, write_sweep
from assurance.campaign.readouts import load_table

KEYS = ["perturbation", "severity", "key"]


def test_replay_at_the_run_threshold_reproduces_every_recorded_decision(tiny_campaign):
    images, cands = load_table(tiny_campaign["run"], "images"), load_table(tiny_campaign["run"], "candidates")
    for monitor in sorted(set(cands["monitor"])):
        im, ca = images[images["monitor"] == monitor], cands[cands["monitor"] == monitor]
        got = replay(im, ca, float(ca["threshold"].iloc[0])).merge(im[[*KEYS, "h_decision", "action"]], on=KEYS)
        assert len(got) == len(im)
        assert np.array_equal(got["h_decision_x"], got["h_decision_y"]), monitor
        assert (got["action_x"] == got["action_y"]).all(), monitor


def _toy() -> tuple[pd.DataFrame, pd.DataFrame]:
    """Two images: image a has an unsafe top candidate (score 0.9) then a safe one (0.2); image b one safe
    candidate (0.5). The default area is unsafe in a, safe in b."""
    base = {"perturbation": "none", "severity": 3, "monitor": "m", "threshold": 0.5}
    images = pd.DataFrame([
        {**base, "key": "a", "h_default": 1.0, "h_top": 1.0, "fault": "", "h_decision": 0.1},
        {**base, "key": "b", "h_default": 0.0, "h_top": 0.3, "fault": "", "h_decision": 0.3},
    ])
    cands = pd.DataFrame([
        {**base, "key": "a", "rank": 0, "score": 0.9, "true_hazard": 1.0, "true_unsafe": True},
        {**base, "key": "a", "rank": 1, "score": 0.2, "true_hazard": 0.1, "true_unsafe": False},
        {**base, "key": "b", "rank": 0, "score": 0.5, "true_hazard": 0.3, "true_unsafe": False},
    ])
    return images, cands


def test_replay_follows_reject_iff_score_above_threshold():
    images, cands = _toy()
    assert list(replay(images, cands, 1.0)["h_decision"]) == [1.0, 0.3]   # all accepted: the top candidates
    assert list(replay(images, cands, 0.5)["h_decision"]) == [0.1, 0.3]   # score 0.5 is not above 0.5
    assert list(replay(images, cands, 0.1)["h_decision"]) == [1.0, 0.0]   # all rejected: the default areas
    assert list(replay(images, cands, 1.0, "score")["h_decision"]) == [0.1, 0.3]  # lowest score first
    assert list(replay(images, cands, 0.1, "score")["h_decision"]) == [1.0, 0.0]
    faulty = images.assign(fault=["fault: read: x", ""])
    assert list(replay(faulty, cands, 1.0)["action"]) == ["default", "land"]


def test_sweep_choice_has_the_fewest_unsafe_landings():
    images, cands = _toy()
    table = sweep(images, cands, "m")
    assert set(table["threshold"]) >= {0.2, 0.5, 0.9}
    assert set(table["walk"]) == {"hazard"}
    both = sweep(images, cands, "m", walks=["hazard", "score"])
    assert choose(both[both["walk"] == "score"]).g_star >= choose(table).g_star
    best = choose(table)
    # 0.2 and 0.5 both avoid the unsafe top candidate; at 0.2 image b takes its (safer) default area
    assert best.unsafe_landings == 0 and best.threshold == 0.2
    assert best.g_star == pytest.approx(((1.0 - 0.1) + (0.0 - 0.0)) / 2)
    at_run = table[table["threshold"] == 0.5].iloc[0]
    assert at_run["miss_rate"] == 0.0 and at_run["fp_rate"] == 0.0


def test_sweep_refuses_a_run_without_scores():
    images, cands = _toy()
    with pytest.raises(SweepError, match="no candidate scores"):
        sweep(images, cands.assign(score=np.nan), "m")
    with pytest.raises(SweepError, match="no configuration 'x'"):
        sweep(images, cands, "x")


def test_sweep_files_are_written(tmp_path):
    images, cands = _toy()
    table, choices = sweep_run(images, cands)
    md = write_sweep(tmp_path, table, choices)
    assert "m (chosen)" in md and "m (run)" in md
    assert (tmp_path / "sweep.png").stat().st_size > 1000
    assert pd.read_csv(tmp_path / "sweep.csv")["threshold"].nunique() == table["threshold"].nunique()


def test_g_rm_counts_an_image_without_candidates_against_the_default_area():
    images, cands = _toy()
    empty = images.iloc[[1]].assign(key="c", h_top=float("nan"), h_default=1.0)
    table = sweep(pd.concat([images, empty], ignore_index=True), cands, "m", thresholds=[0.5])
    row = table.iloc[0]
    assert row["images"] == 3 and row["unsafe_landings"] == 1  # c's default area
    # a: 1.0 -> 0.1 (the unsafe top candidate rejected), b: 0.3 -> 0.3, c: no candidate, 1.0 -> 1.0
    assert row["g_rm"] == pytest.approx((0.9 + 0.0 + 0.0) / 3)
