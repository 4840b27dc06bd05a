"""The one decision walk (el.monitors.walk): hazard rank (the paper's) or ascending monitor score, for every caller."""

from __future__ import annotations

import pytest
from helpers import OracleSegmenter, scene_ids, scene_image
from hypothesis import given
from hypothesis import strategies as st

from el.base.decision import MonitorVerdict
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.monitors import parse_monitor_spec
from el.monitors.spec import walk_of
from el.monitors.walk import ALL_REJECTED, NO_CANDIDATE, select, walk_candidates, walk_order

WW = 128


def test_walk_is_a_spec_parameter_of_registered_monitors_only():
    spec = parse_monitor_spec("learned: walk=SCORE, threshold=0.8")
    assert spec.name == "learned:walk=score,threshold=0.8" and spec.walk == "score"
    assert "walk" not in spec.kwargs() and spec.base.name == "learned:walk=score"
    assert parse_monitor_spec("msp:walk=hazard").name == "msp"  # the default walk is left out of the name
    assert parse_monitor_spec("msp").walk == "hazard" and parse_monitor_spec("lhd").walk == "hazard"
    assert walk_of("msp:walk=score") == "score" and walk_of("lhd+ch:tau=0.25") == "hazard"
    for bad, needle in (("msp:walk=zigzag", "walk must be one of"), ("lhd:walk=score", "takes no parameter")):
        with pytest.raises(ValueError, match=needle):
            parse_monitor_spec(bad)


@given(st.lists(st.tuples(st.booleans(), st.floats(-5, 5)), max_size=12))
def test_score_walk_lands_on_the_accepted_candidate_with_the_lowest_score(items):
    accepted, scores = [a for a, _ in items], [s for _, s in items]
    ok = [k for k in range(len(items)) if accepted[k]]
    want = min(ok, key=lambda k: (scores[k], k)) if ok else None
    verdicts = [MonitorVerdict("m", a, "test", 0.5, s) for a, s in items]  # no threshold: any verdict
    by_score = walk_candidates(len(items), verdicts.__getitem__, "score")
    by_hazard = walk_candidates(len(items), verdicts.__getitem__, "hazard")
    assert select(accepted, scores, "score") == want == by_score.selected
    assert select(accepted, scores, "hazard") == (ok[0] if ok else None) == by_hazard.selected
    assert sorted(walk_order(scores, "score")) == list(range(len(items)))
    assert by_score.examined == len(items) and by_score.overhead_s == 0.5 * len(items)
    assert by_hazard.examined == (ok[0] + 1 if ok else len(items))
    assert sum(v is not None for v in by_hazard.verdicts) == by_hazard.examined  # nothing judged past it
    assert by_hazard.reason == ("accepted" if ok else (NO_CANDIDATE if not items else ALL_REJECTED))


def test_evaluation_mode_judges_every_candidate_without_changing_the_decision():
    verdicts = [MonitorVerdict("m", a, "test", 1.0, 0.0) for a in (False, True, False, True)]
    seen = []
    outcome = walk_candidates(4, verdicts.__getitem__, evaluate_all=True, before=lambda k, real: seen.append(real))
    assert outcome.selected == 1 and outcome.examined == 2 and outcome.overhead_s == 2.0
    assert seen == [True, True, False, False] and None not in outcome.verdicts
    assert walk_candidates(3, None).selected == 0 and walk_candidates(0, None).reason == NO_CANDIDATE
    with pytest.raises(ValueError, match="not a MonitorVerdict"):
        walk_candidates(1, lambda k: (True, "ok"))


class ByIndex:
    """A monitor whose score is given per candidate (by its position in the ranked list)."""

    def __init__(self, scores, threshold):
        self.scores, self.threshold, self.seen = scores, threshold, []

    def check(self, rgb, cand, segmenter, *, seed=0, context=None):
        k = len(self.seen)
        self.seen.append(k)
        s = self.scores[k]
        return MonitorVerdict("byindex", s <= self.threshold, "test", 0.001, s, self.threshold)


@pytest.mark.parametrize("monitor, expected", [("msp:walk=score", "min"), ("msp", "first")])
def test_pipeline_walks_as_its_spec_says(monitor, expected):
    el = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor=monitor),
                          segmenter=OracleSegmenter(WW))
    image = scene_image(scene_ids())
    n = len(EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="none"),
                             segmenter=OracleSegmenter(WW)).decide(image).candidates)
    assert n >= 3
    scores = [0.9 - 0.1 * k for k in range(n)]  # the last-ranked candidate scores lowest
    scores[0] = 2.0  # the top one is rejected
    el.monitor = ByIndex(scores, threshold=1.0)
    d = el.decide(image)
    assert d.action == "land"
    if expected == "min":
        assert d.selected == n - 1 and el.monitor.seen == list(range(n))  # every candidate judged first
        assert d.timings["overhead_s"] == pytest.approx(0.001 * n)
    else:
        assert d.selected == 1 and el.monitor.seen == [0, 1]  # the walk stops at the first accepted


@pytest.mark.parametrize("verdict, message", [
    (MonitorVerdict("m", True, "x", 0.1, float("nan"), 0.5), "non-finite score"),
    (MonitorVerdict("m", "False", "x", 0.1, 0.2, 0.5), "must be true or false"),
    (MonitorVerdict("m", True, "x", 0.1, 0.9, 0.5), "contradicts score 0.9 at threshold 0.5"),
])
def test_the_walk_refuses_a_verdict_it_cannot_act_on(verdict, message):
    """Any monitor's verdict (a plugin's too) is checked where the walk acts on it: flight and campaign alike."""
    with pytest.raises(ValueError, match=message):
        walk_candidates(1, lambda k: verdict)


def test_a_campaign_records_a_verdict_it_cannot_act_on_as_a_fault(tiny_campaign):
    """The campaign checks verdicts inside the task (as the walk does), so a bad plugin verdict is a recorded
    fault of that task, never a crash of the campaign."""
    from assurance.campaign.run import CampaignConfig, plan, run_task
    from el.monitors import Monitor, registry
    from el.monitors.spec import GenericSpec

    class Contradicts(Monitor):  # a plain flight Monitor, as a plugin may write one
        spec = GenericSpec("contradicts", ())

        def __init__(self, *, threshold=None, margin=0.25, max_side=None, clock=None):
            super().__init__(threshold=threshold)

        def check(self, hd, candidate, segmenter, *, seed=0, context=None):
            return MonitorVerdict(self.name, True, "accepts above its threshold", 0.0, 1.0, 0.0)

    registry.register_monitor("contradicts", Contradicts)
    try:
        config = CampaignConfig(perturbations=("none",), monitors=("contradicts",), images=1,
                                core=tiny_campaign["config"].core)
        rows = run_task(plan(tiny_campaign["data"], config)[0], config, OracleSegmenter(tiny_campaign["config"]
                                                                                        .core.working_width))
    finally:
        registry.unregister_monitor("contradicts")
    assert "contradicts score 1 at threshold 0" in rows["images"][0]["fault"] and rows["candidates"] == []
