"""EL-R02: the safety radius holds in metres under the declared height and pitch errors (synthetic scenes), with
R, beta and the pose-error box the registry's targets (parameters radius_m, beta, pose_error)."""

from __future__ import annotations

import pytest

from assurance.fitting.pose_study import PoseCase, candidate_clearances, summarise
from el.geometry.camera import SafetyParams


@pytest.mark.requirements("EL-R02")
def test_no_geometric_clearance_violation_under_pose_errors(requirement_registry):
    p = requirement_registry.parameters
    he, pe = p["pose_error"]["height"], p["pose_error"]["pitch"]
    safety = SafetyParams(radius_m=p["radius_m"], beta=p["beta"])
    # the nominal pose and the three corners of the error box that stretch the ground most differently
    cases = [PoseCase(0.0, 0.0), PoseCase(-he, pe), PoseCase(he, -pe), PoseCase(-he, -pe)]
    df = candidate_clearances([3], size=(960, 540), modes=("exact",), cases=cases, working_width=512, safety=safety)
    cands = df[df["candidate"] >= 0]
    assert len(cands) >= 10, "too few candidates to say anything"
    geometric = cands[cands["cause"] == "geometry"]
    assert geometric.empty, geometric.to_string()
    table = summarise(df, radius_m=safety.radius_m)
    assert set(table["mode"]) == {"exact"} and (table["candidates"] > 0).all()
