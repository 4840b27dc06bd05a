"""The monitored decision loop: fail-safe default action, time budget, monitor coverage (EL-R03/04/06/07)."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from helpers import FakeClock, OracleSegmenter, scene_ids, scene_image
from hypothesis import given, settings
from hypothesis import strategies as st

from assurance.dataio.uavid import write_image
from el.base.decision import decision_schema
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig

W, H, WW = 256, 144, 128


def make(monitor="lhd", *, segmenter=None, clock=None, budget=10.0, evaluate_all=False, **kw):
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor=monitor, time_budget_s=budget,
                         evaluate_all=evaluate_all)
    seg = segmenter if segmenter is not None else OracleSegmenter(WW, **kw)
    kwargs = {"clock": clock} if clock is not None else {}
    return EmergencyLanding(cfg, segmenter=seg, **kwargs)


@pytest.mark.requirements("EL-R04")
def test_lands_on_an_accepted_candidate():
    d = make().decide(scene_image(scene_ids()))
    assert d.action == "land" and d.reason == "accepted"
    chosen = d.candidates[d.selected]
    assert chosen.monitor is not None and chosen.monitor.accepted
    assert all(c.monitor is None for c in d.candidates[d.selected + 1 :])  # the walk stopped there
    jsonschema.validate(json.loads(d.to_json()), decision_schema())


@pytest.mark.requirements("EL-R03")
def test_no_candidate_gives_default_action():
    ids = np.full((H, W), 2, np.uint8)  # all road
    d = make().decide(scene_image(ids))
    assert (d.action, d.reason, d.selected) == ("default", "no_candidate", None)
    assert d.default_area.y + d.default_area.radius_px == pytest.approx(H)


@pytest.mark.requirements("EL-R03", "EL-R04")
def test_all_rejected_gives_default_action():
    # The patch segmentation sees road everywhere: the monitor rejects every candidate.
    seg = OracleSegmenter(WW)
    road = np.eye(8, dtype=np.float32)[2][:, None, None]
    seg.predict_patch = lambda rgb: road * np.ones((1, *rgb.shape[:2]), np.float32)
    d = make(segmenter=seg).decide(scene_image(scene_ids()))
    assert (d.action, d.reason) == ("default", "all_rejected")
    assert d.candidates and all(c.monitor is not None and not c.monitor.accepted for c in d.candidates)


@pytest.mark.requirements("EL-R06")
def test_nan_scores_give_default_action():
    d = make(nan=True).decide(scene_image(scene_ids()))
    assert d.action == "default" and d.reason.startswith("fault: segmentation")


@pytest.mark.requirements("EL-R06")
def test_monitor_exception_gives_default_action():
    seg = OracleSegmenter(WW)

    def boom(rgb):
        raise RuntimeError("monitor crashed")

    seg.predict_patch = boom
    d = make(segmenter=seg).decide(scene_image(scene_ids()))
    assert d.action == "default" and "fault: monitoring" in d.reason and "monitor crashed" in d.reason


@pytest.mark.requirements("EL-R06")
def test_corrupt_image_file_gives_default_action(tmp_path):
    good = tmp_path / "frame.png"
    write_image(good, scene_image(scene_ids()))
    bad = tmp_path / "cut.png"
    bad.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    d = make().decide(bad)
    assert d.action == "default" and d.reason.startswith("fault: read") and "cut.png" in d.reason
    assert make().decide(tmp_path / "missing.png").reason.startswith("fault: read")
    assert make().decide(good).action == "land"


@pytest.mark.requirements("EL-R06")
@pytest.mark.parametrize("shape,dtype", [((H, W, 4), np.uint8), ((H, W), np.uint8), ((H, W, 3), np.float32)])
def test_malformed_arrays_give_default_action(shape, dtype):
    d = make().decide(np.zeros(shape, dtype))
    assert d.action == "default" and d.reason.startswith("fault: read")


@pytest.mark.requirements("EL-R06")
def test_missing_weights_give_default_action(tmp_path):
    el = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW)), weights=tmp_path / "none.pt")
    d = el.decide(scene_image(scene_ids()))
    assert d.action == "default" and d.reason.startswith("fault: model") and "none.pt" in d.reason


@pytest.mark.requirements("EL-R07")
def test_budget_already_spent_gives_timeout():
    clock = FakeClock(step=100.0)  # every reading of the clock costs 100 s
    d = make(clock=clock, budget=1.0).decide(scene_image(scene_ids()))
    assert (d.action, d.reason) == ("default", "timeout")


@pytest.mark.requirements("EL-R07")
def test_budget_exceeded_during_monitoring():
    clock = FakeClock()
    seg = OracleSegmenter(WW)
    real = seg.predict_patch

    def slow(rgb):
        clock.t += 4.0  # each patch costs 4 s on the injected clock
        return real(rgb)

    seg.predict_patch = slow
    d = make(segmenter=seg, clock=clock, budget=3.0).decide(scene_image(scene_ids()))
    assert (d.action, d.reason) == ("default", "timeout")
    d2 = make(segmenter=seg, clock=clock, budget=30.0).decide(scene_image(scene_ids()))
    assert d2.action == "land"


def test_no_monitor_lands_on_top_candidate():
    d = make(monitor="none").decide(scene_image(scene_ids()))
    assert d.action == "land" and d.selected == 0 and d.candidates[0].monitor is None


def test_evaluation_mode_judges_every_candidate_and_keeps_the_walk():
    img = scene_image(scene_ids())
    walk = make().decide(img)
    ev = make(evaluate_all=True).decide(img)
    assert ev.selected == walk.selected and ev.action == walk.action
    assert all(c.monitor is not None for c in ev.candidates)
    assert 0 <= ev.timings["overhead_s"] <= ev.timings["monitoring_s"]


@pytest.mark.requirements("EL-R04", "EL-R11")
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), road=st.integers(10, 200), monitor=st.sampled_from(
    ["lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.9", "lhd+ch+mcd:tau=0.125,n=10,rho=0.5"]))
def test_every_landing_is_on_a_monitor_accepted_candidate(seed, road, monitor):
    img = scene_image(scene_ids(road_col=road, seed=seed))
    d = make(monitor).decide(img)
    if d.action == "land":
        c = d.candidates[d.selected]
        assert c.monitor is not None and c.monitor.accepted
        assert all(p.monitor is not None and not p.monitor.accepted for p in d.candidates[: d.selected])
    else:
        assert d.selected is None
    again = make(monitor).decide(img)
    strip = lambda dec: [(c.x, c.y, c.radius_px, c.hazard, c.monitor and c.monitor.accepted) for c in dec.candidates]  # noqa: E731
    assert (again.action, again.reason, again.selected, strip(again)) == (d.action, d.reason, d.selected, strip(d))


def test_bad_monitor_spec_fails_at_configuration():
    with pytest.raises(ValueError, match="lhd"):
        PipelineConfig(monitor="lhd+foo")


def test_a_frame_decoded_once_is_recorded_as_its_file(tmp_path):
    """``decide(FrameFile.read(path))``: the caller keeps the decoded pixels and the decision is the one the path
    gives, recorded as that file (path, SHA-256, size); a pose passed with its source is recorded with it."""
    from el.base.hashing import sha256_file
    from el.flight.pipeline import FrameFile
    from el.geometry.camera import Pose

    path = tmp_path / "frame.png"
    write_image(path, scene_image(scene_ids()))
    frame = FrameFile.read(path)
    system = make()
    a, b = system.decide(path), system.decide(frame)
    assert frame.rgb.shape == (H, W, 3) and b.input["sha256"] == sha256_file(path) == a.input["sha256"]
    assert (a.action, a.selected, a.reason, a.input["path"]) == (b.action, b.selected, b.reason, b.input["path"])
    typed = system.decide(frame, pose=Pose(height_m=48.0, pitch_deg=45.0), pose_source="command_line")
    assert typed.input["pose"] == {"height_m": 48.0, "pitch_deg": 45.0, "source": "command_line"}
    assert system.decide(frame, pose=Pose(height_m=48.0, pitch_deg=45.0)).input["pose"]["source"] == "frame"
    assert a.input["pose"]["source"] == "nominal"
    jsonschema.validate(json.loads(typed.to_json()), decision_schema())
    bad = system.decide(frame, pose=Pose(height_m=48.0, pitch_deg=45.0), pose_source="guessed")
    assert bad.action == "default" and bad.reason.startswith("fault: pose") and "guessed" in bad.reason


def test_a_frame_decoded_before_the_call_counts_against_the_budget(tmp_path):
    """The decode of a :class:`FrameFile` (done before ``decide``) counts as ``decide(path)``'s own read does: in
    the frame's ``read_s`` and against the time budget."""
    from dataclasses import replace

    from el.flight.pipeline import FrameFile

    path = tmp_path / "frame.png"
    write_image(path, scene_image(scene_ids()))
    frame = FrameFile.read(path)
    assert frame.read_s > 0
    slow = replace(frame, read_s=30.0)  # a decode that took longer than the budget
    system = make(budget=10.0)
    late = system.decide(slow)
    assert late.action == "default" and "timeout" in late.reason
    assert system.decide(frame).reason != late.reason


def test_the_pose_sources_are_the_decision_schema_s():
    from el.flight.kernel import POSE_SOURCES

    schema = decision_schema()["properties"]["input"]["properties"]["pose"]["properties"]["source"]
    assert tuple(schema["enum"]) == POSE_SOURCES


def test_the_flight_system_builds_its_parts_once_and_keeps_what_failed(tmp_path):
    """``EmergencyLanding`` builds its ``parts`` once (``el.flight.kernel.build_parts``); a part that cannot fly is
    kept in
    ``errors`` with its exception and the first is every decision's fault."""
    from el.flight.kernel import Parts

    system = make()
    assert isinstance(system.parts, Parts) and system.parts is system.parts and system.errors == {}
    assert system.parts.labels == system.labels and system.parts.record == system.config.to_dict()
    broken = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd",
                                             gate=str(tmp_path / "missing.json")), segmenter=OracleSegmenter(WW))
    assert set(broken.errors) == {"frame_gate"} and broken.parts.gate is None
    assert broken.fault.startswith("fault: frame_gate: FrameGateError") and str(broken.errors["frame_gate"]) in \
        broken.fault
    assert broken.decide(scene_image(scene_ids())).reason == broken.fault


def test_a_file_that_cannot_be_read_is_named_in_the_decision(tmp_path):
    d = make().decide(tmp_path / "missing.png")
    assert d.reason.startswith("fault: read") and d.input["path"] == str(tmp_path / "missing.png")
