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
from el.monitors.verifier import DEFAULT_VERIFIER, load_verifier
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
    verifier = load_verifier()  # the deployed monitor: the verifier fused with the learned monitor
    assert verifier.body["fusion"]["learned_sha256"] == digest  # fused with the shipped learned model
    assert verifier.body["weights"]["sha256"] == weights
    assert load_calibration(DEPLOYED_CALIBRATION).body["monitor_model"]["sha256"] == verifier.sha256  # calibrated on it
    for f in (DEPLOYED_CALIBRATION, DEFAULT_MODEL, DEFAULT_MODEL.with_name("frame_gate.json"), DEFAULT_VERIFIER,
              DEFAULT_VERIFIER.with_name("verifier_calibration.json"),
              DEFAULT_MODEL.with_name("learned_calibration.json")):
        assert "/work/" not in f.read_text() and "\\\\" not in f.read_text()  # no machine paths recorded


def test_the_evidence_names_every_file_the_deployed_monitor_reads():
    """The deployed spec fuses the verifier with the learned monitor: the data record, the AMLAS index and the model
    log name both files and their development data, not only the calibration card."""
    from assurance.evidence.model_log import monitor_rows
    from assurance.evidence.records import development_sets, model_cards, monitor_files

    manifest = {"config": {"monitors": [DEPLOYED_MONITOR, "lhd"]}}
    found = monitor_files(manifest, DEPLOYED_CALIBRATION)
    assert found["verifier.json"] == DEFAULT_VERIFIER and found["learned.json"] == DEFAULT_MODEL
    assert found["calibration.json"] == DEPLOYED_CALIBRATION
    _, monitors = model_cards(manifest, DEPLOYED_CALIBRATION)
    roles = {row["role"]: row for row in development_sets(None, monitors, package={n: True for n in found})}
    assert {"candidate verifier training", "candidate verifier selection", "learned monitor training",
            "learned monitor selection", "monitor calibration (threshold)"} <= set(roles)
    training = load_verifier().body["training"]
    assert roles["candidate verifier training"]["sha256"] == training["sha256"]
    assert roles["candidate verifier training"]["balance"].startswith(
        f"{training['unsafe']} unsafe of {training['crops']} crops ({training['candidates']} candidates")
    items = {row["item"]: row["value"] for row in monitor_rows(monitors)}
    assert "256 px crops" in items["Candidate verifier"]
    assert "fused with the learned monitor" in items["Candidate verifier"]
    assert items["Calibration card"].startswith("verifier:fuse=learned,walk=score: ")
    folder = load_verifier().body["splits"]["train"]
    assert folder.startswith("data/train") and roles["candidate verifier training"]["path"] == folder  # no note
    assert load_verifier().body["onnx"]["sha256"][:16] in items["Candidate verifier"]
    from assurance.evidence.argument import monitor_words

    assert monitor_words(DEPLOYED_MONITOR) == "candidate verifier fused with the learned runtime monitor"
