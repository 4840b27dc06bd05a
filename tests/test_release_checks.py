"""Campaign checks the release run leans on: EL-R04 under the score walk, and EL-R10 saying by how much."""

from __future__ import annotations

import pandas as pd

from assurance import requirements as rq
from assurance.requirements.checks import check_monitor_coverage, check_unsafe_landing_bound, images_needed_at
from assurance.requirements.records import FAIL, PASS


def _readouts(monitor: str, selected: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    base = {"perturbation": "none", "severity": 3, "monitor": monitor, "key": "seq00/000000"}
    images = pd.DataFrame([{**base, "fault": "", "candidates": 3, "action": "land", "selected": selected}])
    cands = pd.DataFrame([{**base, "rank": k, "accepted": True, "score": s, "selected": k == selected}
                          for k, s in enumerate([0.5, 0.1, 0.3])])
    return images, cands


def test_monitor_coverage_follows_each_configurations_walk():
    assert check_monitor_coverage(*_readouts("msp:walk=score", 1)).status == PASS    # lowest score
    bad = check_monitor_coverage(*_readouts("msp:walk=score", 0))
    assert bad.status == FAIL and "candidate 1, walked before, was accepted" in bad.rows[0]["problem"]
    assert check_monitor_coverage(*_readouts("msp", 0)).status == PASS               # hazard walk: the top one
    assert check_monitor_coverage(*_readouts("msp", 1)).status == FAIL


def test_images_needed_at_an_observed_rate():
    assert images_needed_at(0.0, 0.05) == rq.images_needed(0.05) == 59
    assert images_needed_at(0.03, 0.05) > 200 and images_needed_at(0.05, 0.05) is None
    assert images_needed_at(0.2, 0.05) is None


def test_unsafe_landing_failure_says_by_how_much():
    table = pd.DataFrame([{"perturbation": "none", "severity": 3, "monitor": "m", "images": 70,
                           "unsafe_landing_rate": 7 / 70}])
    ev = check_unsafe_landing_bound(table, "m", 0.05, ["none"], 0.95)
    row = ev.rows[0]
    assert ev.status == FAIL and abs(row["upper_bound"] - 0.17963) < 5e-5   # computed at 95%, not read
    assert abs(row["over_bound_by"] - (row["upper_bound"] - 0.05)) < 1e-12 and row["confidence"] == "95%"
    assert row["images_needed"] == "none at this rate" and row["unsafe_landings"] == 7


def test_harness_errors_share_the_project_root():
    from assurance.analysis.headline import HeadlineError
    from assurance.analysis.sweep import SweepError
    from assurance.campaign.readouts import DamagedRunError, RunError
    from assurance.errors import CommandError
    from assurance.requirements import RegistryError
    from el.base.errors import UavElError

    for cls in (CommandError, HeadlineError, RunError, DamagedRunError, RegistryError, SweepError):
        assert issubclass(cls, UavElError), cls
    assert all(issubclass(c, ValueError) for c in (HeadlineError, RunError, RegistryError, SweepError))
