"""A waiver stands only for an existing, failed requirement, a declared owner and an expiry within the maximum."""

from __future__ import annotations

import datetime as dt

from assurance.evidence.waivers import waiver_problems

TODAY = dt.date(2026, 11, 25)
STATES = {"EL-R09": "verified", "EL-R10": "failed"}


def _w(expires="2027-03-01", owner="segmentation maintainers"):
    return {"reason": "r", "tracked_by": "t", "owner": owner, "expires": expires}


def test_a_proper_waiver_stands():
    assert waiver_problems({"EL-R10": _w()}, STATES, owners=["segmentation maintainers"], today=TODAY) == []


def test_unknown_passing_unowned_and_far_waivers_are_named():
    problems = waiver_problems({"EL-R99": _w(), "EL-R09": _w(), "EL-R10": _w("9999-12-31", "nobody")}, STATES,
                               owners=["segmentation maintainers"], max_days=180, today=TODAY)
    text = "\n".join(problems)
    assert "EL-R99, which is not a requirement" in text
    assert "EL-R09, which is verified" in text
    assert "owned by 'nobody'" in text
    assert "expires 9999-12-31, more than 180 days ahead" in text


def test_without_a_declared_owner_list_any_owner_is_accepted():
    assert waiver_problems({"EL-R10": _w(owner="anyone")}, STATES, today=TODAY) == []


def test_the_gate_policy_cannot_be_overridden_as_a_target():
    import pytest

    from assurance import requirements as rq

    with pytest.raises(rq.TargetError, match="the gate's policy is the registry's"):
        rq.load_registry(targets={"size_limited": ["EL-R01"]})
