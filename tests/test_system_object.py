"""The system under assessment is built once (``assurance.system.System``) and both the flight configuration and a
campaign's are made from it: the same network, label set, CM configuration, declared domain, monitor and gate."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from assurance.cli.system_options import assessed
from assurance.system import default_system
from assurance.system.find import load_system
from assurance.system.system import System
from el.classes.labels import UAVID
from el.flight.pipeline import DEPLOYED_GATE, DEPLOYED_MONITOR


def test_the_embedded_default_is_the_shipped_system():
    system = System.build(default_system())
    assert system.shipped_network and system.labels == UAVID and system.gate == DEPLOYED_GATE
    assert system.deployed() == (DEPLOYED_MONITOR, None)  # held to the shipped card by check_monitor_bindings
    config = system.flight_config()
    assert config.gate.path == str(DEPLOYED_GATE) and config.monitor == DEPLOYED_MONITOR
    assert config.odd == system.odd and config.core == system.core and config.time_budget_s == system.budget_s


def test_a_gate_given_or_none_wins_and_another_network_gets_no_shipped_gate(tmp_path: Path):
    assert System.build(default_system(), gate="none").gate is None
    assert System.build(default_system(), gate=tmp_path / "g.json").gate == tmp_path / "g.json"
    assert System.build(default_system(), model=str(tmp_path / "net.pt")).gate is None  # bound to its network


def test_a_file_naming_only_a_card_deploys_the_cards_monitor(tmp_path: Path):
    from el.flight.pipeline import DEPLOYED_CALIBRATION

    f = tmp_path / "uav-el.toml"
    f.write_text(f'format = "uav-el-system/1"\n[monitor]\ncalibration = "{DEPLOYED_CALIBRATION}"\n', "utf-8")
    system = System.build(load_system(f))
    monitor, card = system.deployed()
    assert card == DEPLOYED_CALIBRATION and monitor == json.loads(DEPLOYED_CALIBRATION.read_text())["body"]["monitor"]


def test_a_command_builds_its_system_once():
    args = argparse.Namespace(system_file=default_system(), weights=None, gate=None)
    first = assessed(args)
    assert assessed(args) is first


def test_a_malformed_section_stops_the_build_naming_the_key(tmp_path: Path):
    f = tmp_path / "uav-el.toml"
    f.write_text('format = "uav-el-system/1"\n[odd]\nperturbations = { snow = 3 }\n', "utf-8")
    with pytest.raises(ValueError, match="odd.perturbations"):
        System.build(load_system(f))
