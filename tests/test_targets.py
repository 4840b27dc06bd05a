"""The requirement targets: EL-R10 at the configured confidence, targets as validated parameters, requirement
texts rendered from them, and the targets bound to the requirement results and the evidence gate."""

from __future__ import annotations

import pandas as pd
import pytest
from scipy import stats

from assurance import requirements as rq
from assurance.analysis.metrics import clopper_pearson_upper


# ------------------------------------------------------------------------------------------------
# EL-R10 honours its confidence
# ------------------------------------------------------------------------------------------------
def _table(k: int, n: int, monitor: str = "m") -> pd.DataFrame:
    # the table's fixed 95% column is left out on purpose: the check computes its own bound
    return pd.DataFrame([{"perturbation": "none", "severity": 3, "monitor": monitor, "images": n,
                          "unsafe_landing_rate": k / n}])


def test_one_sided_bound_known_values_and_the_two_sided_relation():
    assert clopper_pearson_upper(0, 70, 0.95) == pytest.approx(0.0419, abs=5e-5)
    assert clopper_pearson_upper(0, 300, 0.99) == pytest.approx(0.0152, abs=5e-5)
    assert clopper_pearson_upper(0, 300, 0.99) == pytest.approx(1 - 0.01 ** (1 / 300), rel=1e-12)
    for k, n, conf in ((0, 300, 0.99), (3, 300, 0.95), (7, 70, 0.9)):
        one_sided = stats.binomtest(k, n, alternative="less").proportion_ci(confidence_level=conf, method="exact")
        two_sided = stats.binomtest(k, n).proportion_ci(confidence_level=2 * conf - 1, method="exact")
        assert clopper_pearson_upper(k, n, conf) == pytest.approx(one_sided.high, rel=1e-9)
        assert one_sided.high == pytest.approx(two_sided.high, rel=1e-9)  # one-sided c = two-sided 2c - 1


def test_el_r10_0_of_300_at_99_percent_is_not_verified():
    """The reported bug: 0 unsafe landings in 300 images, bound 0.01 at 99%: the 99% bound is 0.0152, so the
    sample cannot show 0.01 (the 95% bound, 0.0099, would have)."""
    at95 = rq.check_unsafe_landing_bound(_table(0, 300), "m", 0.01, ["none"], 0.95)
    at99 = rq.check_unsafe_landing_bound(_table(0, 300), "m", 0.01, ["none"], 0.99)
    assert at95.status == rq.PASS
    assert at99.status == rq.INSUFFICIENT and "99% confidence" in at99.summary
    assert at99.rows[0]["upper_bound"] == pytest.approx(0.015233, abs=1e-6)
    assert at99.rows[0]["confidence"] == "99%" and "99%" in at99.name


def test_el_r10_fails_at_99_where_95_passes_and_passes_at_90_where_95_fails():
    # 3 of 300, bound 0.03: 95% bound 0.0256 <= 0.03, 99% bound 0.0331 > 0.03 (and 0 of 300 would show it)
    assert rq.check_unsafe_landing_bound(_table(3, 300), "m", 0.03, ["none"], 0.95).status == rq.PASS
    strict = rq.check_unsafe_landing_bound(_table(3, 300), "m", 0.03, ["none"], 0.99)
    assert strict.status == rq.FAIL and "one-sided 99% upper bound > 0.03" in strict.summary
    assert strict.rows[0]["over_bound_by"] == pytest.approx(0.033093 - 0.03, abs=1e-6)
    # the other way: 0 of 50, bound 0.05: 95% bound 0.058 cannot show it, 90% bound 0.045 does
    assert rq.check_unsafe_landing_bound(_table(0, 50), "m", 0.05, ["none"], 0.95).status == rq.INSUFFICIENT
    loose = rq.check_unsafe_landing_bound(_table(0, 50), "m", 0.05, ["none"], 0.90)
    assert loose.status == rq.PASS and "90%" in loose.summary


def test_the_campaign_check_passes_the_registry_confidence():
    params = {**rq.load_registry().parameters, "unsafe_landing_bound": 0.01, "confidence": 0.99,
              "deployed_monitor": "m", "required_perturbations": ["none"]}
    ctx = rq.CheckContext("no-run", params, table=_table(0, 300))
    ev = rq.CHECKS["unsafe_landing_bound"](ctx)
    assert ev.status == rq.INSUFFICIENT and ev.requirement == "EL-R10" and "99%" in ev.summary
