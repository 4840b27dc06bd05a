"""Requirement tests that need no campaign: the pose-error margin (EL-R14) and weights integrity (EL-R15).

No torch: they run in a base install too (the shipped network's ONNX export), as ``uav-el verify`` runs them."""

from __future__ import annotations

import numpy as np
import pytest

from assurance import requirements as rq
from el.base.errors import WeightsError
from el.base.torch_extra import have_torch
from el.classes.labels import ids_to_colors
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.camera import SafetyParams
from el.geometry.config import CoreConfig
from el.segmentation.factory import load_model
from el.segmentation.weights import DEFAULT_WEIGHTS, load_weights


@pytest.mark.requirements("EL-R14")
@pytest.mark.parametrize("size", [(3840, 2160), (4096, 2160)])
def test_declared_beta_covers_the_declared_pose_error_box(size, requirement_registry):
    p = requirement_registry.parameters  # the targets: R, beta and the pose-error box
    core = CoreConfig(safety=SafetyParams(radius_m=p["radius_m"], beta=p["beta"]))
    ev = rq.check_pose_margin(core, size, p["pose_error"], {"radius_m": p["radius_m"], "beta": p["beta"]})
    assert ev.status == rq.PASS, ev.summary
    assert ev.rows[0]["required_beta"] <= p["beta"]


@pytest.mark.requirements("EL-R14")
def test_a_too_small_beta_is_caught():
    ev = rq.check_pose_margin(CoreConfig(safety=SafetyParams(beta=1.2)), (3840, 2160), {"height": 0.2, "pitch": 0.2})
    assert ev.status == rq.FAIL and "1.2 <" in ev.summary


@pytest.mark.requirements("EL-R14")
def test_a_run_planned_with_other_safety_params_does_not_judge_the_targets():
    core = CoreConfig(safety=SafetyParams(radius_m=2.0, beta=1.7))
    ev = rq.check_pose_margin(core, (3840, 2160), {"height": 0.2, "pitch": 0.2}, {"radius_m": 2.5, "beta": 1.7})
    assert ev.status == rq.INSUFFICIENT and "planned with R = 2 m" in ev.summary and "declare R = 2.5 m" in ev.summary
    same = rq.check_pose_margin(core, (3840, 2160), {"height": 0.2, "pitch": 0.2}, {"radius_m": 2, "beta": 1.7})
    assert same.status == rq.PASS


def _scene() -> np.ndarray:
    """A small colour-coded label image (low vegetation, a road, a building): any frame will do, the model
    fails before it is used."""
    ids = np.full((144, 256), 5, np.uint8)
    ids[:, 80:86] = 2
    ids[:48, 160:192] = 1
    return ids_to_colors(ids)


@pytest.fixture(scope="module")
def shipped_copy(tmp_path_factory):
    """A copy of the shipped weights with their card and checked ONNX export: what any install loads (torch runs the
    weights; a base install, without torch, runs the export, ``el.segmentation.onnx_segmenter``)."""
    import shutil

    folder = tmp_path_factory.mktemp("weights")
    for name in ("model.pt", "model.json", "model.onnx", "model.onnx.json"):
        shutil.copyfile(DEFAULT_WEIGHTS.parent / name, folder / name)
    return folder / "model.pt"


def _altered(src, dst, suffix=".pt"):
    """A copy of the network's files with one bit flipped in the middle of its ``suffix`` file."""
    for name in (".pt", ".json", ".onnx", ".onnx.json"):
        dst.with_suffix(name).write_bytes(src.with_suffix(name).read_bytes())
    target = dst.with_suffix(suffix)
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0x01  # one flipped bit in the middle of the tensors
    target.write_bytes(bytes(data))
    return dst


@pytest.mark.requirements("EL-R15")
def test_altered_weights_are_refused_before_use(shipped_copy, tmp_path):
    load_model(shipped_copy)  # the intact file loads
    bad = _altered(shipped_copy, tmp_path / "altered.pt")
    with pytest.raises(WeightsError, match="SHA-256 mismatch") as exc:
        load_model(bad)
    assert "altered.pt" in str(exc.value)
    if have_torch():  # the torch loader itself checks too
        with pytest.raises(WeightsError, match="SHA-256 mismatch"):
            load_weights(bad)


@pytest.mark.requirements("EL-R15")
def test_an_altered_onnx_export_is_refused_before_use(shipped_copy, tmp_path, monkeypatch):
    monkeypatch.setenv("UAV_EL_ENGINE", "onnx")  # the export must run (auto falls back to torch where it can)
    bad = _altered(shipped_copy, tmp_path / "altered.pt", ".onnx")
    with pytest.raises(WeightsError, match="SHA-256 mismatch") as exc:
        load_model(bad)
    assert "altered.onnx" in str(exc.value)


@pytest.mark.requirements("EL-R15")
def test_weights_without_their_card_are_refused(shipped_copy, tmp_path):
    lone = tmp_path / "lone.pt"
    lone.write_bytes(shipped_copy.read_bytes())
    with pytest.raises(WeightsError, match="model card not found"):
        load_model(lone)


@pytest.mark.requirements("EL-R15", "EL-R06")
def test_pipeline_with_altered_weights_takes_the_default_action(shipped_copy, tmp_path):
    bad = _altered(shipped_copy, tmp_path / "altered.pt")
    el = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=128)), weights=bad)
    d = el.decide(_scene())
    assert d.action == "default" and d.reason.startswith("fault: model") and "SHA-256 mismatch" in d.reason
