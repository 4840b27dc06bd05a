"""The out-of-domain frame gate: fitted on tiny frames with a tiny model, it flags a constant image, noise
and heavy fog; the pipeline ends such frames in the default action (out_of_domain); the gate file is
hash-checked; the shift report writes its table and plot."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import TINY_ARCH, OracleSegmenter, write_textured_scenes

W, H, WW = 128, 72, 64


def _frames(root, seeds):
    return write_textured_scenes(root, seeds, W, H)


@pytest.fixture(scope="module")
def setup(tmp_path_factory, one_torch_thread):
    import torch

    from assurance.fitting.ood_gate import fit_ood
    from el.segmentation.architectures import build_model
    from el.segmentation.inference import Segmenter

    root = tmp_path_factory.mktemp("ood")
    train, val = _frames(root / "train", range(40)), _frames(root / "val", range(100, 120))
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH), working_width=WW, card={"weights_sha256": "7e" * 32})
    doc = fit_ood(train, val, seg, quantile=0.995)
    gate = root / "gate.json"
    gate.write_text(json.dumps(doc))
    return {"seg": seg, "gate": gate, "val": val, "root": root}


def _far_frames(val):
    from assurance.campaign.perturbations import perturb
    from assurance.scenes.uavid import read_image

    normal = read_image(next(val.glob("**/Images/*.png")))
    rng = np.random.default_rng(0)
    return {"constant": np.full((H, W, 3), 128, np.uint8),
            "noise": rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
            "fog": perturb(normal, "fog", 5, np.random.default_rng(1))}


def test_gate_flags_constant_noise_and_heavy_fog(setup):
    from assurance.scenes.uavid import read_image
    from el.monitors.ood import load_ood

    gate = load_ood(setup["gate"])
    assert gate.kind == "trunk" and gate.body["dims"] == 2 * TINY_ARCH.widths[-1]
    normal = [gate.score(setup["seg"], read_image(p)) for p in sorted(setup["val"].glob("**/Images/*.png"))]
    assert np.mean(np.array(normal) <= gate.threshold) >= 0.95
    for name, rgb in _far_frames(setup["val"]).items():
        d = gate.score(setup["seg"], rgb)
        assert d > gate.threshold and d > max(normal), (name, d, gate.threshold, max(normal))


def test_pipeline_takes_the_default_action_out_of_domain(setup, tmp_path):
    from assurance.scenes.uavid import read_image
    from el.monitors.ood import load_ood
    from el.pipeline import EmergencyLanding, PipelineConfig

    gate = load_ood(setup["gate"])
    frames = sorted(setup["val"].glob("**/Images/*.png"))
    inside = min(frames, key=lambda p: gate.score(setup["seg"], read_image(p)))
    from el.config import CoreConfig

    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", ood=str(setup["gate"]), time_budget_s=None)
    el = EmergencyLanding(cfg, segmenter=setup["seg"])
    d = el.decide(inside)
    assert d.reason != "out_of_domain" and not d.reason.startswith("fault"), d.reason
    assert d.input["ood_score"] <= d.input["ood_threshold"] and "ood_s" in d.timings
    for name, rgb in _far_frames(setup["val"]).items():
        d = el.decide(rgb)
        assert d.action == "default" and d.reason == "out_of_domain", name
        assert d.input["ood_score"] > d.input["ood_threshold"]
    doc = json.loads(setup["gate"].read_text())
    doc["body"]["threshold"] = 1e9
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    d = EmergencyLanding(PipelineConfig(monitor="lhd", ood=str(bad)), segmenter=setup["seg"]).decide(inside)
    assert d.action == "default" and d.reason.startswith("fault: ood") and "altered" in d.reason


def test_softmax_fallback_for_segmenters_without_a_trunk(setup):
    from assurance.fitting.ood_gate import embed_frames, fit_ood_body
    from el.monitors.ood import SOFTMAX, OODGate, embedding_kind, frame_embedding

    seg = OracleSegmenter(WW)
    assert embedding_kind(seg) == SOFTMAX
    x = embed_frames(setup["root"] / "train", seg, images=20)
    body = fit_ood_body(x, embed_frames(setup["val"], seg), kind=SOFTMAX)
    gate = OODGate("t", "", body, np.array(body["mean"]), np.array(body["precision"]))
    assert gate.distance(frame_embedding(seg, np.full((H, W, 3), 128, np.uint8))) > gate.threshold


def test_cli_fit_ood_with_report_and_land_refuses_a_bad_gate(setup, tmp_path, capsys, monkeypatch):
    import el.segmentation as seg_module
    from assurance.cli import main

    monkeypatch.setattr(seg_module.Segmenter, "load", classmethod(lambda cls, *a, **k: setup["seg"]))
    out, rep = tmp_path / "g.json", tmp_path / "rep"
    assert main(["fit-ood", "--data", str(setup["root"] / "train"), "--val", str(setup["val"]), "--out", str(out),
                 "--images", "10", "--report", str(rep)]) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "threshold" in text and "fog" in text
    assert {p.name for p in rep.iterdir()} == {"ood_shift.csv", "ood_shift.md", "ood_shift.png"}
    assert (rep / "ood_shift.csv").read_text().splitlines()[0].startswith("perturbation,severity,frames")
    image = next(setup["val"].glob("**/Images/*.png"))
    assert main(["land", str(image), "--ood", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.json" in err[0]
