"""A rate bound is decided at any sample size. Failed when the one-sided Clopper-Pearson lower bound already
exceeds the target, verified when the upper bound is within it (and the run is as large as required), undecidable
only in between; a failed bound fails the evidence gate with its numbers."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pandas as pd
import pytest
from scipy import stats

from assurance import requirements as rq
from assurance.analysis.intervals import (
    BOUND_MET,
    BOUND_MISSED,
    BOUND_UNDECIDED,
    clopper_pearson_interval,
    clopper_pearson_lower,
    clopper_pearson_upper,
    decide_rate_bound,
)
from assurance.evidence.gate import decide_gate
from assurance.requirements.calibration_check import check_calibrated_miss_rate

RELEASE = (("none", 6), ("brightness", 25), ("fog", 28), ("motion_blur", 24), ("shifted_pixels", 9),
           ("pixel_trap", 5))  # the release run's unsafe landings of 70 (assurance/waivers.yaml)


def _table(rows: tuple[tuple[str, int], ...], n: int, monitor: str = "m") -> pd.DataFrame:
    return pd.DataFrame([{"perturbation": p, "severity": 3, "monitor": monitor, "images": n,
                          "unsafe_landing_rate": k / n} for p, k in rows])


# ------------------------------------------------------------------------------------------------
# The decision itself
# ------------------------------------------------------------------------------------------------
def test_seven_unsafe_of_twelve_misses_five_percent_at_any_size():
    d = decide_rate_bound(7, 12, 0.05, 0.95)
    assert d.verdict == BOUND_MISSED
    assert d.lower == pytest.approx(0.3152, abs=5e-5) and d.lower > 0.05
    assert "7 of 12" in d.text() and "lower bound 0.315" in d.text() and "95%" in d.text()


def test_zero_of_twelve_is_not_decided():
    d = decide_rate_bound(0, 12, 0.05, 0.95)
    assert d.verdict == BOUND_UNDECIDED and d.lower == 0.0
    assert d.upper == pytest.approx(1 - 0.05 ** (1 / 12), rel=1e-9) and d.upper > 0.05


def test_zero_of_a_hundred_is_verified_when_the_minimum_run_size_is_met():
    assert decide_rate_bound(0, 100, 0.05, 0.95).verdict == BOUND_MET
    assert decide_rate_bound(0, 100, 0.05, 0.95, min_n=100).verdict == BOUND_MET
    assert decide_rate_bound(0, 100, 0.05, 0.95, min_n=101).verdict == BOUND_UNDECIDED  # too small to verify
    assert decide_rate_bound(7, 12, 0.05, 0.95, min_n=101).verdict == BOUND_MISSED      # never too small to fail


def test_the_boundaries():
    # at n = 12, target 0.05, 95%: 2 unsafe landings leave it open, 3 already show it missed
    assert decide_rate_bound(2, 12, 0.05).verdict == BOUND_UNDECIDED
    assert decide_rate_bound(3, 12, 0.05).verdict == BOUND_MISSED
    # zero unsafe landings show 0.05 from 59 images on (rq.images_needed), not at 58
    assert decide_rate_bound(0, 58, 0.05).verdict == BOUND_UNDECIDED
    assert decide_rate_bound(0, rq.images_needed(0.05), 0.05).verdict == BOUND_MET
    # a bound exactly on the target: the upper one meets it (<=), the lower one does not miss it (strictly >)
    assert decide_rate_bound(1, 70, clopper_pearson_upper(1, 70, 0.95), 0.95).verdict == BOUND_MET
    assert decide_rate_bound(5, 70, clopper_pearson_lower(5, 70, 0.95), 0.95).verdict == BOUND_UNDECIDED
    # no data decides nothing
    d = decide_rate_bound(0, 0, 0.05)
    assert d.verdict == BOUND_UNDECIDED and math.isnan(d.lower) and math.isnan(d.upper)
    with pytest.raises(ValueError, match="target"):
        decide_rate_bound(0, 10, 1.5)


@pytest.mark.parametrize(("k", "n"), [(0, 10), (1, 12), (7, 12), (14, 70), (70, 70)])
@pytest.mark.parametrize("conf", [0.9, 0.95, 0.99])
def test_the_lower_bound_is_scipys_one_sided_and_the_two_sided_at_twice_the_tail(k, n, conf):
    ref = stats.binomtest(k, n, alternative="greater").proportion_ci(confidence_level=conf, method="exact")
    assert clopper_pearson_lower(k, n, conf) == pytest.approx(ref.low, rel=1e-9, abs=1e-12)
    assert clopper_pearson_lower(k, n, conf) == pytest.approx(clopper_pearson_interval(k, n, 2 * conf - 1)[0],
                                                              rel=1e-9, abs=1e-12)


# ------------------------------------------------------------------------------------------------
# EL-R10 and EL-R16
# ------------------------------------------------------------------------------------------------
def test_el_r10_fails_on_seven_of_twelve_with_its_numbers():
    ev = rq.check_unsafe_landing_bound(_table((("none", 7),), 12), "m", 0.05, ["none"], 0.95)
    assert ev.status == rq.FAIL
    assert "one-sided 95% lower bound > 0.05" in ev.summary and "none (s3): 7 of 12, lower bound 0.315" in ev.summary
    row = ev.rows[0]
    assert row["verdict"] == rq.FAIL and row["lower_bound"] == pytest.approx(0.3152, abs=5e-5)
    # the same through the registered check, with the registry's targets
    params = {**rq.load_registry().parameters, "deployed_monitor": "m", "required_perturbations": ["none"]}
    reg_ev = rq.CHECKS["unsafe_landing_bound"](rq.CheckContext("no-run", params, table=_table((("none", 7),), 12)))
    assert reg_ev.status == rq.FAIL and reg_ev.requirement == "EL-R10"


def test_el_r10_small_runs_that_show_nothing_stay_undecided_and_large_clean_ones_pass():
    for k in (0, 2):  # bounds straddle 0.05
        assert rq.check_unsafe_landing_bound(_table((("none", k),), 12), "m", 0.05, ["none"]).status == rq.INSUFFICIENT
    assert rq.check_unsafe_landing_bound(_table((("none", 0),), 100), "m", 0.05, ["none"]).status == rq.PASS
    # one scenario missed decides the requirement, even with another too small to show anything
    mixed = pd.concat([_table((("none", 0),), 12), _table((("fog", 7),), 12)])
    assert rq.check_unsafe_landing_bound(mixed, "m", 0.05, ["none", "fog"]).status == rq.FAIL


def test_el_r10_on_the_release_figures_is_unchanged():
    """Every scenario of the release run still fails: four by their lower bound, none and pixel_trap (lower bounds
    0.038 and 0.029) as before, by an upper bound over 0.05 on 70 images, enough to have shown it."""
    ev = rq.check_unsafe_landing_bound(_table(RELEASE, 70), "m", 0.05, [p for p, _ in RELEASE], 0.95)
    assert ev.status == rq.FAIL and {r["verdict"] for r in ev.rows} == {rq.FAIL}
    by = {r["perturbation"]: r for r in ev.rows}
    assert by["none"]["lower_bound"] < 0.05 < by["shifted_pixels"]["lower_bound"]
    assert "one-sided 95% upper bound > 0.05 under none (s3): 6 of 70" in ev.summary


def _card(miss_rate: float = 0.05) -> SimpleNamespace:
    return SimpleNamespace(spec="m:threshold=0.5", monitor="m", threshold=0.5, network_sha256="n",
                           body={"miss_rate": miss_rate, "confidence": 0.95})


def _candidates(accepted: int, unsafe: int) -> pd.DataFrame:
    return pd.DataFrame([{"perturbation": "none", "monitor": "m:threshold=0.5", "true_unsafe": True,
                          "accepted": i < accepted} for i in range(unsafe)])


def test_el_r16_fails_below_its_minimum_when_the_lower_bound_is_over_the_card():
    ev = check_calibrated_miss_rate(_candidates(7, 12), _card(), min_unsafe=100)
    assert ev.status == rq.FAIL and "7 of 12" in ev.summary and "lower bound 0.315" in ev.summary
    assert "> 0.05" in ev.summary and "fewer than the 100" in ev.summary
    assert check_calibrated_miss_rate(_candidates(0, 12), _card(), min_unsafe=100).status == rq.INSUFFICIENT
    assert check_calibrated_miss_rate(_candidates(2, 12), _card(), min_unsafe=100).status == rq.INSUFFICIENT
    assert check_calibrated_miss_rate(_candidates(0, 100), _card(), min_unsafe=100).status == rq.PASS


# ------------------------------------------------------------------------------------------------
# Through the test outcome and the gate
# ------------------------------------------------------------------------------------------------
def _results(r10: rq.RequirementResult) -> dict[str, rq.RequirementResult]:
    return {"EL-R01": rq.RequirementResult("EL-R01", "t", rq.VERIFIED, "ok", [rq.TestOutcome("t::a", "passed")]),
            "EL-R10": r10}


def test_a_missed_bound_fails_the_gate_even_where_the_run_size_excuses_undecided_ones():
    from assurance.requirements.suite.test_campaign_requirements import judge

    ev = rq.check_unsafe_landing_bound(_table((("none", 7),), 12), "m", 0.05, ["none"], 0.95)
    with pytest.raises(pytest.fail.Exception) as failed:
        judge(ev)
    outcome = rq.TestOutcome("suite::test_campaign_check[EL-R10]", "failed", message=f"Failed: {failed.value.msg}")
    state, reason = rq.requirement_state([outcome])
    gate = decide_gate(_results(rq.RequirementResult("EL-R10", "bound", state, reason, [outcome])), [], None, False,
                       undecidable=["EL-R10"])
    assert gate.result == "FAILED" and gate.blocking == ["EL-R10"] and gate.exit_code(False, None) == 1
    assert "failed (EL-R10)" in gate.text and "none (s3): 7 of 12, lower bound 0.315" in gate.text
    assert "Failed:" not in gate.text and "\n" not in gate.text


def test_an_undecided_bound_is_excused_only_at_a_size_that_cannot_decide_it():
    ev = rq.check_unsafe_landing_bound(_table((("none", 0),), 12), "m", 0.05, ["none"], 0.95)
    outcome = rq.TestOutcome("suite::test_campaign_check[EL-R10]", "skipped", message=ev.summary)
    state, reason = rq.requirement_state([outcome])
    assert state == rq.NOT_VERIFIED
    res = _results(rq.RequirementResult("EL-R10", "bound", state, reason, [outcome]))
    small = decide_gate(res, [], None, False, undecidable=["EL-R10"])
    assert small.result == "INCOMPLETE" and small.exit_code(False, None) == 0
    assert decide_gate(res, [], None, False).exit_code(False, None) == 1
    assert decide_gate(res, [], None, True, undecidable=["EL-R10"]).exit_code(True, None) == 1
