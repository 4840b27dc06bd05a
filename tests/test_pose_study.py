"""EL-R02: the safety radius holds in metres under +-20% height and pitch errors (synthetic scenes)."""

import pytest

from assurance.fitting.pose_study import PoseCase, candidate_clearances, summarise


@pytest.mark.requirements("EL-R02")
def test_no_geometric_clearance_violation_under_pose_errors():
    # the nominal pose and the two corners of the +-20% box that stretch the ground most differently
    cases = [PoseCase(0.0, 0.0), PoseCase(-0.2, 0.2), PoseCase(0.2, -0.2), PoseCase(-0.2, -0.2)]
    df = candidate_clearances([3], size=(960, 540), modes=("exact",), cases=cases, working_width=512)
    cands = df[df["candidate"] >= 0]
    assert len(cands) >= 10, "too few candidates to say anything"
    geometric = cands[cands["cause"] == "geometry"]
    assert geometric.empty, geometric.to_string()
    table = summarise(df)
    assert set(table["mode"]) == {"exact"} and (table["candidates"] > 0).all()
