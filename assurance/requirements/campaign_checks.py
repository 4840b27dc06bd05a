"""The campaign-judged requirements: one registered check each (``@check``, docs/architecture.md 4.8).

Each function reads what it needs from the ``CheckContext`` (run, manifest, readouts, results table,
the registry's parameters) and returns an ``Evidence`` record; the registration order is the order
of the requirement tests and of the evidence report's checks.
"""

from __future__ import annotations

from assurance.paths import card_path
from assurance.requirements import checks as ck
from assurance.requirements import determinism
from assurance.requirements.calibration_check import check_calibrated_miss_rate
from assurance.requirements.catalogue import CheckContext, check
from assurance.requirements.domain_checks import check_outside_domain
from assurance.requirements.records import INSUFFICIENT, Evidence
from el.monitors.calibration import load_calibration


@check("EL-R04")
def monitor_coverage(ctx: CheckContext) -> Evidence:
    """Every 'land' decision of the run is on a monitor-accepted candidate."""
    return ck.check_monitor_coverage(ctx.images, ctx.candidates)


@check("EL-R08", parameters=("required_perturbations", "min_images_per_perturbation"))
def perturbation_coverage(ctx: CheckContext) -> Evidence:
    """Each required perturbation was evaluated on enough images."""
    p = ctx.parameters
    return ck.check_perturbation_coverage(ctx.images, p["required_perturbations"], p["min_images_per_perturbation"])


@check("EL-R09", parameters=("deployed_monitor", "required_perturbations", "min_images_per_perturbation"),
       artefacts=("results_table",))
def safety_gain(ctx: CheckContext) -> Evidence:
    """The deployed monitor's G* lower bound is positive in every scenario."""
    p = ctx.parameters
    return ck.check_safety_gain(ctx.table, p["deployed_monitor"], p["required_perturbations"],
                                p["min_images_per_perturbation"])


@check("EL-R10", parameters=("deployed_monitor", "unsafe_landing_bound", "required_perturbations", "confidence"),
       artefacts=("results_table",))
def unsafe_landing_bound(ctx: CheckContext) -> Evidence:
    """The deployed monitor's unsafe-landing upper bound is within the configured bound in every scenario."""
    p = ctx.parameters
    return ck.check_unsafe_landing_bound(ctx.table, p["deployed_monitor"], p["unsafe_landing_bound"],
                                         p["required_perturbations"], p["confidence"])


@check("EL-R11")
def table_recomputation(ctx: CheckContext) -> Evidence:
    """The results table recomputes identically from the readouts (the report computes its own table)."""
    return determinism.check_table_recomputation(ctx.run, n_boot=100)


@check("EL-R11", parameters=("rerun_shards",), in_report=False)
def shard_rerun(ctx: CheckContext) -> Evidence:
    """Re-run shards give identical readouts (slow, and writes into the work folder: tests only)."""
    shards = int(ctx.parameters["rerun_shards"])
    if shards < 1:
        return Evidence("re-run of campaign shards", INSUFFICIENT,
                        "insufficient evidence: the registry asks for no re-run (parameters.rerun_shards = 0)")
    return determinism.check_rerun(ctx.run, shards=shards, work_dir=ctx.work_dir / "rerun")


@check("EL-R12", readouts=False, artefacts=("report",))
def artefacts_identified(ctx: CheckContext) -> Evidence:
    """The run manifest identifies weights, data, configuration and code."""
    return ck.check_artefacts_identified(ctx.manifest)


@check("EL-R13", parameters=("deployed_monitor", "time_budget_s"))
def decision_time(ctx: CheckContext) -> Evidence:
    """The deployed monitor's decisions are within the time budget."""
    p = ctx.parameters
    return ck.check_decision_time(ctx.images, p["deployed_monitor"], p["time_budget_s"])


@check("EL-R14", parameters=("pose_error", "radius_m", "beta"))
def pose_error_margin(ctx: CheckContext) -> Evidence:
    """The run planned with the declared R and beta, and that beta covers the declared pose-error box at the
    run's input size."""
    size = ctx.input_size
    if size is None:
        return Evidence("pose-error margin of beta", INSUFFICIENT,
                        "insufficient evidence: no evaluated image gives the input size")
    p = ctx.parameters
    return ck.check_pose_margins(ctx.manifest["config"]["core"], size, ck.own_poses(ctx.images), p["pose_error"],
                                 {"radius_m": p["radius_m"], "beta": p["beta"]})


@check("EL-R16", parameters=("calibration_card", "calibration_min_unsafe"))
def calibrated_miss_rate(ctx: CheckContext) -> Evidence:
    """The calibrated monitor's miss rate on the test split is within its card's (no card: not verified)."""
    card = ctx.parameters.get("calibration_card")
    if not card:
        return Evidence("miss rate of the calibrated monitor", INSUFFICIENT,
                        "insufficient evidence: no calibration card chosen (parameters.calibration_card)")
    manifest = ctx.manifest or {}
    return check_calibrated_miss_rate(ctx.candidates, load_calibration(card_path(card)),
                                      run_models=manifest.get("monitor_models"),
                                      run_network=(manifest.get("weights") or {}).get("sha256"),
                                      min_unsafe=int(ctx.parameters.get("calibration_min_unsafe") or 1),
                                      run_data=manifest.get("data"))


@check("EL-R17")
def outside_domain(ctx: CheckContext) -> Evidence:
    """No frame outside the run's declared operating domain ends in a landing; frames outside counted."""
    return check_outside_domain(ctx.images, (ctx.manifest or {}).get("config", {}).get("odd"))
