"""The shipped network flown as its packaged ONNX export keeps the records fitted on it (the shipped frame gate
above all), vouched for by the package's own engine record; any other ONNX file, whatever it claims, does not."""

from __future__ import annotations

import json
import shutil

import pytest

from assurance.system import load_system as load_system_file
from assurance.system.system import System
from el.base.records import network_identities
from el.monitors.frame_gate import bind_frame_gate
from el.segmentation.onnx_engine import SHIPPED_DIR, have_onnxruntime, shipped_export_source

pytestmark = pytest.mark.skipif(not have_onnxruntime(), reason="needs ONNX Runtime (the onnx extra)")

EXPORT = SHIPPED_DIR / "model.onnx"
SMALL = '[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n'


def _system(tmp_path, body: str) -> System:
    path = tmp_path / "uav-el.toml"
    path.write_text(f'format = "uav-el-system/1"\n{SMALL}{body}', encoding="utf-8")
    return System.build(load_system_file(path))


def _shipped_weights_sha() -> str:
    return json.loads((SHIPPED_DIR / "model.json").read_text())["weights_sha256"]


def test_only_the_packaged_export_is_vouched_for():
    record = json.loads((SHIPPED_DIR / "model.onnx.json").read_text())
    assert shipped_export_source(record["onnx_sha256"]) == _shipped_weights_sha()
    assert shipped_export_source(_shipped_weights_sha()) is None
    assert shipped_export_source("0" * 64) is None


def test_the_export_as_a_system_model_carries_the_shipped_gate(tmp_path):
    from el.flight.pipeline import DEPLOYED_GATE

    assert _system(tmp_path, f'[model]\npath = "{EXPORT}"\n').gate == DEPLOYED_GATE
    copy = tmp_path / "net.onnx"  # the same bytes elsewhere are the same network
    shutil.copyfile(EXPORT, copy)
    assert _system(tmp_path, '[model]\npath = "net.onnx"\n').gate == DEPLOYED_GATE
    # a gate the file names, or none, still wins
    assert _system(tmp_path, '[model]\npath = "net.onnx"\n[monitor]\ngate = "none"\n').gate is None


def test_a_changed_export_or_a_class_map_gets_no_shipped_gate(tmp_path):
    changed = tmp_path / "changed.onnx"
    data = bytearray(EXPORT.read_bytes())
    data[-1] ^= 0x01  # one bit: another file, whatever its metadata says of its source
    changed.write_bytes(bytes(data))
    assert _system(tmp_path, '[model]\npath = "changed.onnx"\n').gate is None
    assert shipped_export_source(__import__("el.base.hashing", fromlist=["x"]).sha256_file(changed)) is None


def test_the_gate_binds_to_the_export_and_not_to_another_network(tmp_path):
    from el.base.errors import FrameGateError
    from el.classes.labels import UAVID
    from el.flight.pipeline import DEPLOYED_GATE
    from el.segmentation.onnx_model import load_onnx_model

    model = load_onnx_model(EXPORT, labels=UAVID)
    assert _shipped_weights_sha() in network_identities(model)
    bind_frame_gate(DEPLOYED_GATE, model)  # no FrameGateError: the export is the gate's network
    assert model.frame_stats  # and it returns the statistics the gate reads

    class Other:  # a network claiming the shipped weights' export as its source by an attribute of its own
        weights_sha256 = "1" * 64
        frame_stats = True
        source_weights_sha256 = None

    with pytest.raises(FrameGateError, match="fitted on network"):
        bind_frame_gate(DEPLOYED_GATE, Other())
