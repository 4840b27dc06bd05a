"""Campaign requirement tests: they read a campaign run (--uav-el-run RUN, $UAV_EL_RUN, default runs/demo).

Each test runs one check of ``assurance.requirements`` on the run: a pass passes, a failure fails
with the offending scenarios, and too little data to decide (no run, a missing perturbation, too
few images) skips, which leaves the requirement "not verified", never "failed".
The acceptance parameters (deployed monitor, bounds, image counts) come from the registry.
"""

from __future__ import annotations

import pytest

from assurance import readouts
from assurance import requirements as rq
from assurance.table import results_table

# These read a campaign run (--uav-el-run / $UAV_EL_RUN / runs/demo): the evidence step runs them
# (`pytest -m requirements`), the default test run (`make test`, -m "not campaign") does not.
pytestmark = pytest.mark.campaign


def judge(evidence: rq.Evidence) -> None:
    """Pass, fail with the details, or skip as insufficient evidence."""
    if evidence.status == rq.INSUFFICIENT:
        pytest.skip(evidence.summary if "insufficient" in evidence.summary
                    else f"insufficient evidence: {evidence.summary}")
    if evidence.status == rq.FAIL:
        pytest.fail(evidence.message(), pytrace=False)


@pytest.fixture(scope="module")
def tables(campaign_run):
    images = readouts.load_table(campaign_run, "images")
    if images.empty:
        pytest.skip(f"insufficient evidence: {campaign_run} has no finished shard")
    return images, readouts.load_table(campaign_run, "candidates")


@pytest.fixture(scope="module")
def table(campaign_run, tables):
    return results_table(campaign_run)


@pytest.fixture(scope="module")
def params(requirement_registry):
    return requirement_registry.parameters


@pytest.mark.requirements("EL-R04")
def test_monitor_coverage_every_landing_on_an_accepted_candidate(tables):
    judge(rq.check_monitor_coverage(*tables))


@pytest.mark.requirements("EL-R08")
def test_perturbation_coverage_all_six_with_enough_images(tables, params):
    images, _ = tables
    judge(rq.check_perturbation_coverage(images, params["required_perturbations"],
                                         params["min_images_per_perturbation"]))


@pytest.mark.requirements("EL-R09")
def test_safety_gain_lower_bound_positive_under_every_perturbation(table, params):
    judge(rq.check_safety_gain(table, params["deployed_monitor"], params["required_perturbations"],
                               params["min_images_per_perturbation"]))


@pytest.mark.requirements("EL-R10")
def test_unsafe_landing_rate_upper_bound_within_configured_bound(table, params):
    judge(rq.check_unsafe_landing_bound(table, params["deployed_monitor"], params["unsafe_landing_bound"],
                                        params["required_perturbations"], params["confidence"]))


@pytest.mark.requirements("EL-R11")
def test_determinism_results_table_recomputes_identically(campaign_run, tables):
    judge(rq.check_table_recomputation(campaign_run))


@pytest.mark.requirements("EL-R11")
def test_determinism_rerun_of_shards_gives_identical_readouts(campaign_run, tables, params, tmp_path):
    if params["rerun_shards"] < 1:
        pytest.skip("insufficient evidence: the registry asks for no re-run (parameters.rerun_shards = 0)")
    judge(rq.check_rerun(campaign_run, shards=params["rerun_shards"], work_dir=tmp_path / "rerun"))


@pytest.mark.requirements("EL-R12")
def test_run_manifest_identifies_the_artefacts(campaign_run):
    judge(rq.check_artefacts_identified(readouts.read_manifest(campaign_run)))


@pytest.mark.requirements("EL-R13")
def test_decision_time_of_the_deployed_monitor_within_budget(tables, params):
    images, _ = tables
    judge(rq.check_decision_time(images, params["deployed_monitor"], params["time_budget_s"]))


@pytest.mark.requirements("EL-R14")
def test_beta_of_the_run_covers_the_pose_error_box(campaign_run, tables, params):
    images, _ = tables
    ok = images[images["fault"].fillna("") == ""]
    if ok.empty:
        pytest.skip("insufficient evidence: no evaluated image gives the input size")
    first = ok.iloc[0]
    size = (int(round(2 * first["default_x"])), int(round(first["default_y"] + first["default_r"])))
    core = readouts.read_manifest(campaign_run)["config"]["core"]
    judge(rq.check_pose_margin(core, size, params["pose_error"]))


@pytest.mark.requirements("EL-R16")
def test_calibrated_monitor_miss_rate_within_its_card(tables, params):
    from assurance.calibration import check_calibrated_miss_rate
    from el.monitors.calibration import load_calibration

    card = params.get("calibration_card")
    if not card:
        pytest.skip("insufficient evidence: no calibration card chosen (parameters.calibration_card)")
    judge(check_calibrated_miss_rate(tables[1], load_calibration(card)))
