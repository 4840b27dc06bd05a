"""Monitor scores: the paper's 21 configurations keep their verdicts, and each verdict follows the score."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from paper_cases import disc_mask, paper_cases

from el.classes.labels import UAVID
from el.monitors import PAPER_GRID, build_monitor

FROZEN = json.loads((Path(__file__).parent / "data" / "paper_verdicts.json").read_text())["verdicts"]


@pytest.fixture(scope="module")
def cases():
    return paper_cases()


def _features(spec: str, case):
    softmax, samples = case
    return samples if "mcd" in spec else softmax


@pytest.mark.parametrize("spec", PAPER_GRID)
def test_paper_specs_give_the_recorded_verdicts(spec, cases):
    assert len(FROZEN) == 21 and spec in FROZEN
    monitor, mask = build_monitor(spec, labels=UAVID), disc_mask()
    got = [monitor.check_scores(_features(spec, c), mask) for c in cases]
    assert [[v.accepted, v.reason] for v in got] == FROZEN[spec]
    assert 0 < sum(v.accepted for v in got) < len(got)  # the cases exercise both verdicts


@pytest.mark.parametrize("spec", PAPER_GRID)
def test_verdict_is_score_above_threshold_and_moves_with_it(spec, cases):
    """Rejected iff score > threshold (the stated rule), at the default threshold 0 and at any other."""
    mask = disc_mask()
    base = build_monitor(spec, labels=UAVID)
    assert base.threshold == 0.0 and base.name == spec
    verdicts = [base.check_scores(_features(spec, c), mask) for c in cases]
    scores = [v.score for v in verdicts]
    assert all((not v.accepted) == (v.score > 0.0) and v.threshold == 0.0 for v in verdicts)
    assert all(0.0 < s <= 1.0 or s < 0.0 for s in scores)  # a fraction of rejected pixels, or a margin < 0
    for t in sorted({0.0, -0.05, 0.02, 0.1, *scores})[::4]:
        tuned = build_monitor(f"{spec}{',' if ':' in spec else ':'}threshold={t!r}", labels=UAVID)
        got = [tuned.check_scores(_features(spec, c), mask) for c in cases]
        assert [v.score for v in got] == scores  # the threshold moves the verdict, never the score
        assert [v.accepted for v in got] == [not s > t for s in scores]
    # monotone: a higher threshold never rejects a candidate a lower one accepts
    accepted_at = {t: sum(not s > t for s in scores) for t in (-1.0, -0.1, 0.0, 0.05, 0.5, 1.0)}
    assert list(accepted_at.values()) == sorted(accepted_at.values())


def test_threshold_in_the_spec_round_trips_and_default_is_the_plain_name():
    from el.monitors import parse_monitor_spec

    assert build_monitor("lhd:threshold=0", labels=UAVID).name == "lhd"
    m = build_monitor("lhd+ch+mcd:threshold=0.01,tau=0.25,n=10,rho=0.9", labels=UAVID)
    assert m.name == "lhd+ch+mcd:tau=0.25,n=10,rho=0.9,threshold=0.01" and m.threshold == 0.01
    assert parse_monitor_spec(m.name).base.name == "lhd+ch+mcd:tau=0.25,n=10,rho=0.9"
    for bad in ("lhd:threshold=nan", "lhd:threshold=inf", "lhd:threshold=x"):
        with pytest.raises(ValueError, match="valid forms"):
            parse_monitor_spec(bad)


def test_reason_says_when_the_threshold_overrides_the_rule(cases):
    mask = disc_mask()
    lenient = build_monitor("lhd:threshold=0.5", labels=UAVID)
    flips = [(v, c) for c in cases if not (v := build_monitor("lhd", labels=UAVID).check_scores(c[0], mask)).accepted]
    v = lenient.check_scores(flips[0][1][0], mask)
    assert v.accepted and "forbidden class" in v.reason and "<= threshold 0.5" in v.reason


def test_campaign_sharing_gives_the_same_scores_as_each_monitor_alone(cases):
    """judge_candidates shares features and reductions between configurations: same verdicts and scores."""
    import numpy as np

    from assurance.campaign.judging import judge_candidates
    from el.base.decision import Disc

    class Fixed:  # serves the frozen cases by patch: case i sits at column 20 i of a one-row image
        def predict_patch(self, rgb):
            return cases[int(rgb[0, 0, 0])][0]

        def mc_dropout(self, rgb, n, keep_prob, seed):
            return cases[int(rgb[0, 0, 0])][1][:n]

    hd = np.zeros((9, 20 * len(cases), 3), np.uint8)
    discs = []
    for i in range(len(cases)):
        hd[:, 20 * i: 20 * i + 9] = i
        discs.append(Disc(20 * i + 4.5, 4.5, 4.0))
    monitors = [build_monitor(s, margin=0.0, labels=UAVID) for s in PAPER_GRID]
    assert monitors[0].patch(hd, discs[0]).disc_mask.tolist() == disc_mask().tolist()
    rows = judge_candidates(hd, discs, monitors, Fixed(), seed=0)
    for j, spec in enumerate(PAPER_GRID):
        assert [[r[j].accepted, r[j].reason] for r in rows] == FROZEN[spec]
        alone = [monitors[j].check_scores(_features(spec, c), disc_mask()).score for c in cases]
        assert [r[j].score for r in rows] == alone
