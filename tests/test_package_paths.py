"""Packaged data is found from the package, never from the working directory: the calibration card the registry
names, the shipped waivers (for the shipped system only), and a targets file's card relative to that file."""

from __future__ import annotations

import json

from assurance import requirements as rq
from assurance.paths import PACKAGE_ROOT
from assurance.system import build as system_build
from assurance.system import default_system
from assurance.system.find import load_system


def test_the_registry_card_is_package_data_whatever_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    card = rq.card_path(rq.load_registry().parameters["calibration_card"])
    assert card.is_file() and card.is_relative_to(PACKAGE_ROOT)
    from el.monitors.calibration import load_calibration

    assert load_calibration(card).body["spec"]
    assert rq.card_path(None) is None and rq.card_path(str(tmp_path / "c.json")) == tmp_path / "c.json"


def test_a_targets_files_card_is_relative_to_that_file(tmp_path, monkeypatch):
    (tmp_path / "cfg").mkdir()
    f = tmp_path / "cfg" / "targets.json"
    f.write_text(json.dumps({"calibration_card": "calib.json", "confidence": 0.9}))
    monkeypatch.chdir(tmp_path)
    assert rq.read_targets_file(f)["calibration_card"] == str(tmp_path / "cfg" / "calib.json")


def test_the_shipped_waivers_are_the_shipped_systems_default_only(tmp_path):
    shipped = system_build.waivers(default_system())
    assert shipped and shipped.endswith("waivers.yaml")
    from assurance.evidence import load_waivers

    assert "EL-R10" in load_waivers(shipped)
    mine = tmp_path / "uav-el.toml"
    mine.write_text('[system]\nname = "mine"\n')
    assert system_build.waivers(load_system(mine)) is None  # not the shipped system's deviations
    (tmp_path / "w.yaml").write_text("waivers: []\n")
    mine.write_text('[system]\nname = "mine"\n[waivers]\nfile = "w.yaml"\n')
    assert system_build.waivers(load_system(mine)) == str(tmp_path / "w.yaml")
    assert system_build.waivers(load_system(mine), "given.yaml") == "given.yaml"
