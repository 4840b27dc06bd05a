"""Campaign requirement tests: they read the campaign run the session is bound to (--uav-el-run RUN, $UAV_EL_RUN,
ini uav_el_run, default runs/demo; ``uav-el verify RUN`` passes it).

One test per registered campaign check (``assurance.requirements.CHECKS``, docs/architecture.md 4.8),
each claiming its check's requirement: a pass passes, a failure fails with the offending scenarios,
and too little data to decide (no run, a missing perturbation, too few images) skips, which leaves
the requirement "not verified", never "failed". The acceptance parameters (deployed monitor, bounds,
image counts) come from the registry.
"""

from __future__ import annotations

import pytest

from assurance import requirements as rq

# These read a campaign run: the evidence step runs them (`uav-el verify`), a fast test run (-m "not campaign")
# does not.
pytestmark = pytest.mark.campaign


def judge(evidence: rq.Evidence) -> None:
    """Pass, fail with the details, or skip as insufficient evidence."""
    if evidence.status == rq.INSUFFICIENT:
        pytest.skip(evidence.summary if "insufficient" in evidence.summary
                    else f"insufficient evidence: {evidence.summary}")
    if evidence.status == rq.FAIL:
        pytest.fail(evidence.message(), pytrace=False)


@pytest.fixture(scope="module")
def context(campaign_run, requirement_registry):
    """The run's check context, shared by the checks of this module (each table loaded once)."""
    return rq.CheckContext(campaign_run, requirement_registry.parameters)


@pytest.mark.parametrize("spec", [
    pytest.param(c, id=f"{c.requirement}-{c.name}", marks=pytest.mark.requirements(c.requirement))
    for c in rq.CHECKS.values()
])
def test_campaign_check(spec: rq.Check, context: rq.CheckContext, tmp_path) -> None:
    if spec.readouts and context.images.empty:
        pytest.skip(f"insufficient evidence: {context.run} has no finished shard")
    judge(spec(context.with_work_dir(tmp_path)))
