"""A fitted record is bound to the network it was fitted on: the learned monitor, the calibration card and the
out-of-domain gate refuse a segmenter with another weights hash (flight: default action with the reason;
command line: one line, exit 2)."""

from __future__ import annotations

import json

import pytest
from helpers import OracleSegmenter, scene_ids, scene_image

from assurance.cli import main
from el.base.errors import CalibrationError, FrameGateError, LearnedModelError
from el.classes.labels import UAVID
from el.flight.pipeline import DEPLOYED_CALIBRATION, DEPLOYED_MONITOR, EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.monitors import build_monitor
from el.monitors.calibration import card_document, load_calibration
from el.monitors.frame_gate import load_frame_gate
from el.monitors.learned import DEFAULT_MODEL, load_learned_model
from el.segmentation.weights import DEFAULT_WEIGHTS, read_card

WW = 128
SHIPPED = read_card(DEFAULT_WEIGHTS)["weights_sha256"]
OTHER = "ab" * 32
SHIPPED_GATE = DEFAULT_MODEL.with_name("frame_gate.json")


class Network(OracleSegmenter):
    """A perfect segmenter that reports a weights hash, as a user's network loaded from a file would."""

    def __init__(self, weights_sha256: str | None) -> None:
        super().__init__(WW)
        self.weights_sha256 = weights_sha256


def _decide(segmenter, **config):
    return EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), **config),
                            segmenter=segmenter).decide(scene_image(scene_ids()))


def test_shipped_records_are_bound_to_the_shipped_network():
    for record in (load_learned_model(labels=UAVID), load_calibration(DEPLOYED_CALIBRATION),
                   load_frame_gate(SHIPPED_GATE)):
        assert record.network_sha256 == SHIPPED
        record.check_network(Network(SHIPPED))  # the network they were fitted on passes
    errors = (LearnedModelError, CalibrationError, FrameGateError)
    shipped = (load_learned_model(labels=UAVID), load_calibration(DEPLOYED_CALIBRATION), load_frame_gate(SHIPPED_GATE))
    for record, error in zip(shipped,
                             errors, strict=True):
        for other in (OTHER, None):  # another network, or one that cannot say which it is
            with pytest.raises(error, match="fitted on network 0d3dab88c2b0"):
                record.check_network(Network(other))


@pytest.mark.parametrize("other", [OTHER, None])
def test_the_deployed_monitor_refuses_another_network_in_flight(other):
    d = _decide(Network(other))  # the default configuration: the deployed monitor (verifier and learned) and its card
    assert d.action == "default" and d.reason.startswith("fault: monitor: LearnedModelError")
    assert "fitted on network 0d3dab88c2b0" in d.reason and "refit" in d.reason
    with pytest.raises(LearnedModelError):
        build_monitor(DEPLOYED_MONITOR, labels=UAVID).check_network(Network(other))


def test_a_calibration_card_refuses_another_network_in_flight(tmp_path):
    body = dict(json.loads(DEPLOYED_CALIBRATION.read_text())["body"])
    body.update(monitor="lhd", spec="lhd:threshold=0.05", threshold=0.05, monitor_model={"sha256": None},
                weights={"path": None, "sha256": OTHER, "segmenter": "weights"})
    card = tmp_path / "card.json"
    card.write_text(json.dumps(card_document(body)))
    assert _decide(Network(OTHER), monitor="lhd", calibration=str(card)).action == "land"  # its own network
    d = _decide(Network(SHIPPED), monitor="lhd", calibration=str(card))
    assert d.action == "default" and d.reason.startswith("fault: monitor: CalibrationError")
    assert "calibration card fitted on network abababababab" in d.reason


def test_a_frame_gate_refuses_another_network_in_flight():
    d = _decide(Network(OTHER), monitor="lhd", gate=str(SHIPPED_GATE))
    assert d.action == "default" and d.reason.startswith("fault: frame_gate: FrameGateError")
    assert "fitted on network" in d.reason


def test_the_command_line_refuses_another_network_with_exit_2(tiny_campaign, tmp_path, capsys):
    image = next((tiny_campaign["data"]).glob("**/Images/*.png"))
    weights = str(tiny_campaign["weights"])  # a real weights file with its card: another network
    cases = [
        ["land", str(image), "--weights", weights],  # the deployed monitor
        ["land", str(image), "--weights", weights, "--monitor", "lhd", "--gate", str(SHIPPED_GATE)],
        ["campaign", "--data", str(tiny_campaign["data"]), "--out", str(tmp_path / "run"), "--weights", weights,
         "--monitors", "lhd", "--calibration", str(DEPLOYED_CALIBRATION), "--quiet"],
    ]
    for argv in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "fitted on network 0d3dab88c2b0" in err[0], err
    assert not (tmp_path / "run").exists()  # refused before any task ran


def test_a_record_that_names_no_network_is_refused_everywhere(tmp_path):
    from el.monitors.learned import model_document

    body = dict(json.loads(DEFAULT_MODEL.read_text())["body"], weights={"path": None, "sha256": None})
    unbound = tmp_path / "learned.json"
    unbound.write_text(json.dumps(model_document(body)))
    for network in (Network(None), Network(OTHER), Network(SHIPPED)):  # two unidentified networks are not one
        with pytest.raises(LearnedModelError, match="the record names no network"):
            load_learned_model(unbound, labels=UAVID).check_network(network)


def test_el_r16_fails_on_a_run_made_with_another_network():
    import pandas as pd

    from assurance.requirements.calibration_check import check_calibrated_miss_rate

    card = load_calibration(DEPLOYED_CALIBRATION)
    rows = pd.DataFrame({"perturbation": ["none"] * 2, "monitor": [card.spec] * 2, "true_unsafe": [True, True],
                         "accepted": [False, False], "score": [0.99, 0.98]})
    models = {card.spec: card.body["monitor_model"]["sha256"]}
    assert check_calibrated_miss_rate(rows, card, run_models=models, run_network=SHIPPED).status == "pass"
    other = check_calibrated_miss_rate(rows, card, run_models=models, run_network=OTHER)
    assert other.status == "fail" and "calibrated on network 0d3dab88c2b0" in other.summary
    assert check_calibrated_miss_rate(rows, card, run_models=models, run_network=None).status == "insufficient"


def test_a_campaign_refuses_a_monitor_bound_to_another_network(tiny_campaign, tmp_path):
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign

    config = CampaignConfig(perturbations=("none",), monitors=(DEPLOYED_MONITOR,), images=1,
                            core=tiny_campaign["config"].core)
    with pytest.raises(LearnedModelError, match="fitted on network 0d3dab88c2b0"):
        run_campaign(tiny_campaign["data"], tmp_path / "run", config, segmenter=Network(OTHER),
                     execution=Execution(progress=False))
    assert not (tmp_path / "run").exists()
