"""The deployed spec's threshold is its card's: a spec that carries another threshold than the calibration card
it runs with is refused (flight: the default action with the reason; command line: one line, exit 2). A user's
``--monitor X:threshold=T`` with no card is an override, not a mismatch."""

from __future__ import annotations

import json

import pytest
from helpers import OracleSegmenter, scene_ids, scene_image

import el.flight.pipeline
from assurance.cli import main
from el.base.errors import CalibrationError
from el.flight.pipeline import DEPLOYED_CALIBRATION, DEPLOYED_MONITOR, EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.monitors.calibration import card_document, check_card_spec, load_calibration
from el.segmentation.weights import DEFAULT_WEIGHTS, read_card

WW = 128
SHIPPED_T = load_calibration(DEPLOYED_CALIBRATION).threshold
BASE = load_calibration(DEPLOYED_CALIBRATION).monitor  # the deployed spec without its threshold


class Shipped(OracleSegmenter):
    """A perfect segmenter that reports the shipped network's weights hash (the shipped card's network)."""

    def __init__(self) -> None:
        super().__init__(WW)
        self.weights_sha256 = read_card(DEFAULT_WEIGHTS)["weights_sha256"]


def _resealed_card(path, threshold: float):
    """The shipped card at another threshold, re-hashed (a card that checks, calibrating another threshold)."""
    body = dict(json.loads(DEPLOYED_CALIBRATION.read_text())["body"])
    body.update(threshold=threshold, spec=f"{BASE},threshold={threshold!r}")
    path.write_text(json.dumps(card_document(body)))
    return path


def _decide(**config):
    return EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), time_budget_s=None, **config),
                            segmenter=Shipped()).decide(scene_image(scene_ids()))


def test_a_spec_runs_with_its_card_only_at_the_card_s_threshold(tmp_path):
    card = load_calibration(DEPLOYED_CALIBRATION)
    check_card_spec(card, DEPLOYED_MONITOR)  # the shipped pair
    check_card_spec(card, BASE)  # no threshold of its own: it runs at the card's
    with pytest.raises(CalibrationError) as err:
        check_card_spec(card, f"{BASE},threshold=0.5")
    line = str(err.value)
    assert "\n" not in line and str(DEPLOYED_CALIBRATION) in line
    assert f"'{BASE},threshold=0.5' has threshold 0.5" in line and f"threshold {SHIPPED_T!r}" in line
    with pytest.raises(CalibrationError, match=f"calibrates '{BASE}', not 'lhd'"):
        check_card_spec(card, "lhd")
    with pytest.raises(CalibrationError, match="not 'none'"):
        check_card_spec(card, None)


def test_in_flight_a_spec_off_its_card_s_threshold_is_the_default_action(tmp_path, monkeypatch):
    assert not _decide().reason.startswith("fault"), "the shipped pair flies"
    d = _decide(monitor=f"{BASE},threshold=0.5", calibration=str(DEPLOYED_CALIBRATION))
    assert d.action == "default" and d.reason.startswith("fault: monitor: CalibrationError")
    assert "has threshold 0.5" in d.reason and repr(SHIPPED_T) in d.reason
    # the deployed spec with its card swapped for one re-hashed at another threshold
    monkeypatch.setattr(el.flight.pipeline, "DEPLOYED_CALIBRATION", _resealed_card(tmp_path / "card.json", 0.9))
    d = _decide()
    assert d.action == "default" and d.reason.startswith("fault: monitor: CalibrationError")
    assert f"has threshold {SHIPPED_T!r}" in d.reason and "card has threshold 0.9" in d.reason
    # a user's threshold with no card is an override, not a card mismatch
    assert not _decide(monitor="lhd:threshold=0.3").reason.startswith("fault")


def _system(tmp_path, spec: str, card) -> str:
    path = tmp_path / "uav-el.toml"
    path.write_text(f'[monitor]\nspec = "{spec}"\ncalibration = "{card}"\n')
    return str(path)


def test_the_command_line_refuses_a_deployed_spec_off_its_card_s_threshold(tmp_path, capsys):
    card = _resealed_card(tmp_path / "card.json", 0.9)
    system = _system(tmp_path, DEPLOYED_MONITOR, card)
    image = tmp_path / "frame.png"
    from assurance.dataio.uavid import write_image
    from el.classes.labels import ids_to_colors

    write_image(image, ids_to_colors(scene_ids()))
    for argv in (["land", str(image), "--system", system],
                 ["campaign", "--data", str(tmp_path / "data"), "--out", str(tmp_path / "run"), "--system", system,
                  "--quiet"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert system in err[0] and str(card) in err[0] and DEPLOYED_MONITOR in err[0], err[0]
        assert f"has threshold {SHIPPED_T!r}" in err[0] and "card has threshold 0.9" in err[0], err[0]
    assert not (tmp_path / "run").exists()
    # a card given on the command line with a spec of its own threshold: the same line, from the card
    assert main(["land", str(image), "--monitor", f"{BASE},threshold=0.5", "--calibration",
                 str(DEPLOYED_CALIBRATION)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has threshold 0.5" in err[0] and str(DEPLOYED_CALIBRATION) in err[0], err


def test_a_system_whose_spec_matches_its_card_or_that_has_no_card_is_not_refused(tmp_path):
    from assurance.system import build as system_build
    from assurance.system import default_system, load_system

    system_build.check_deployed_calibration(default_system())  # the shipped pair
    card = _resealed_card(tmp_path / "card.json", 0.9)
    system_build.check_deployed_calibration(load_system(_system(tmp_path, f"{BASE},threshold=0.9", card)))
    (tmp_path / "only.toml").write_text('[monitor]\nspec = "lhd:threshold=0.3"\n')
    assert system_build.deployed_card(load_system(tmp_path / "only.toml")) is None
