"""A registry or targets weaker than the system's is named parameter by parameter; model files changed after a run
are named; EL-R16 is judged by its bound, with a minimum sample, on the test split only."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from assurance import requirements as rq
from assurance.campaign.model_files import changed_model_files, model_files
from assurance.requirements.weakening import parameter_weakenings, registry_weakenings
from el.classes.labels import UAVID

pytestmark = pytest.mark.requirements("EL-R12")


def test_each_parameter_is_ranked_its_own_way():
    ref = {"unsafe_landing_bound": 0.05, "confidence": 0.95, "required_perturbations": ["none", "fog"],
           "size_limited": ["EL-R08"], "pose_error": {"height": 0.2, "pitch": 0.2}, "deployed_monitor": "lhd"}
    stronger = {"unsafe_landing_bound": 0.01, "confidence": 0.99, "required_perturbations": ["none", "fog", "x"],
                "size_limited": [], "pose_error": {"height": 0.3, "pitch": 0.2}, "deployed_monitor": "lhd"}
    assert parameter_weakenings(ref, stronger) == []
    weaker = {"unsafe_landing_bound": 0.999, "confidence": 0.5, "required_perturbations": ["none"],
              "size_limited": ["EL-R08", "EL-R04"], "pose_error": {"height": 0.1, "pitch": 0.2},
              "deployed_monitor": "lhd+ch"}
    lines = parameter_weakenings(ref, weaker)
    assert len(lines) == 6
    text = "\n".join(lines)
    assert "unsafe_landing_bound = 0.999 is higher (looser) than the system's 0.05" in text
    assert "confidence = 0.5 is lower (looser)" in text
    assert "required_perturbations: fog missing" in text and "size_limited: EL-R04 added" in text
    assert "pose_error: height smaller (looser)" in text and "deployed_monitor = 'lhd+ch' is different" in text
    assert parameter_weakenings({"confidence": 0.95}, {}) == ["parameter confidence is missing (the system's: 0.95)"]
    assert parameter_weakenings({"confidence": 0.95}, {"confidence": "high"})  # not comparable: not as strong


def test_a_registry_file_is_compared_with_the_system_s(tmp_path):
    shipped = rq.load_registry(None)
    text = rq.default_registry_path().read_text(encoding="utf-8")
    weak = tmp_path / "weak.yaml"
    weak.write_text(text.replace("min_images_per_perturbation: 10", "min_images_per_perturbation: 1"))
    lines = registry_weakenings(shipped, rq.load_registry(weak))
    assert lines == [f"{weak}: parameter min_images_per_perturbation = 1 is lower (looser) than the system's 10"]
    strong = tmp_path / "strong.yaml"
    strong.write_text(text.replace("min_images_per_perturbation: 10", "min_images_per_perturbation: 20"))
    assert registry_weakenings(shipped, rq.load_registry(strong)) == []
    assert registry_weakenings(shipped, shipped.with_targets({"unsafe_landing_bound": 0.01})) == []
    loose = shipped.with_targets({"unsafe_landing_bound": 0.2}, source="t.json")
    assert "unsafe_landing_bound = 0.2 is higher (looser)" in registry_weakenings(shipped, loose)[0]
    card = tmp_path / "card.json"
    card.write_text("{}")
    other_card = shipped.with_targets({"calibration_card": str(card)}, source="t.json")
    assert "another card than the system's" in registry_weakenings(shipped, other_card)[0]


def test_a_model_file_changed_after_the_run_is_named(tmp_path):
    w = tmp_path / "net.pt"
    w.write_bytes(b"weights")
    recorded = model_files({"path": str(w)}, [], UAVID)
    assert str(w) in recorded and "el/monitors/data/learned.json" in recorded  # the packaged ones, by package path
    assert changed_model_files(recorded) == ([], [])
    w.write_bytes(b"other weights")
    problems, unchecked = changed_model_files(recorded)
    assert len(problems) == 1 and problems[0].startswith(f"{w}: changed since the run was made")
    w.unlink()
    assert changed_model_files(recorded) == ([], [str(w)])


class _Card:
    def __init__(self, miss_rate: float, confidence: float = 0.95, split_sha: str = "cal") -> None:
        self.spec, self.monitor, self.threshold, self.network_sha256 = "m:threshold=0.5", "m", 0.5, None
        self.body = {"miss_rate": miss_rate, "confidence": confidence, "split": {"sha256": split_sha}}


def _rows(n: int, accepted: int) -> pd.DataFrame:
    return pd.DataFrame({"perturbation": ["none"] * n, "monitor": ["m:threshold=0.5"] * n, "true_unsafe": [True] * n,
                         "accepted": [i < accepted for i in range(n)]})


def test_el_r16_is_judged_by_its_bound_with_a_minimum_sample_on_the_test_split():
    from assurance.requirements.calibration_check import check_calibrated_miss_rate as r16

    test = {"sha256": "test", "splits": {"test": 30}}
    assert r16(_rows(200, 168), _Card(0.8), run_data=test).status == rq.PASS  # 0.84 > 0.8, lower bound 0.791 <= 0.8
    assert r16(_rows(200, 170), _Card(0.8), run_data=test).status == rq.FAIL  # lower bound 0.802 > 0.8
    few = r16(_rows(3, 0), _Card(0.8), min_unsafe=100, run_data=test)
    assert few.status == rq.INSUFFICIENT and "fewer than the 100" in few.summary
    train = r16(_rows(200, 10), _Card(0.8), run_data={"sha256": "x", "splits": {"train": 3}})
    assert train.status == rq.INSUFFICIENT and "declare the split(s) train" in train.summary
    own = r16(_rows(200, 10), _Card(0.8), run_data={"sha256": "cal", "splits": {}})
    assert own.status == rq.INSUFFICIENT and "calibrated on" in own.summary
    assert json.dumps(r16(_rows(200, 10), _Card(0.8), run_data=test).rows[0])  # the row is plain data
