"""The deployed configuration is one thing: the flight code's default, the registry's, and its calibration card."""

from __future__ import annotations

from assurance.requirements import card_path, load_registry
from el.base.hashing import sha256_file
from el.base.records import read_signed
from el.classes.labels import UAVID
from el.flight.pipeline import DEPLOYED_CALIBRATION, DEPLOYED_MONITOR, PipelineConfig
from el.monitors import build_monitor, parse_monitor_spec
from el.monitors.calibration import load_calibration
from el.monitors.learned import DEFAULT_MODEL
from el.segmentation.weights import DEFAULT_WEIGHTS


def test_flight_default_registry_and_card_name_the_same_configuration():
    params = load_registry().parameters
    card = load_calibration(DEPLOYED_CALIBRATION)
    assert PipelineConfig().monitor_name == DEPLOYED_MONITOR == params["deployed_monitor"] == card.spec
    assert card_path(params["calibration_card"]).resolve() == DEPLOYED_CALIBRATION  # package data, wherever installed
    assert parse_monitor_spec(DEPLOYED_MONITOR).walk == "score"
    assert build_monitor(DEPLOYED_MONITOR, labels=UAVID).threshold == card.body["threshold"]


def test_shipped_monitor_files_rest_on_the_shipped_weights():
    weights = sha256_file(DEFAULT_WEIGHTS)
    assert load_calibration(DEPLOYED_CALIBRATION).body["weights"]["sha256"] == weights
    body, digest = read_signed(DEFAULT_MODEL, "uav-el-learned-monitor/1", "learned monitor", ValueError)
    assert body["weights"]["sha256"] == weights
    assert load_calibration(DEPLOYED_CALIBRATION).body["monitor_model"]["sha256"] == digest  # calibrated on it
    for f in (DEPLOYED_CALIBRATION, DEFAULT_MODEL, DEFAULT_MODEL.with_name("frame_gate.json")):
        assert "/work/" not in f.read_text() and "\\\\" not in f.read_text()  # no machine paths recorded
