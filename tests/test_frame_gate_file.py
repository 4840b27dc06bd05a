"""The deployable frame gate: ``uav-el fit-gate`` writes a hash-checked file bound to its network; with
it the pipeline records the gate's score and threshold in every decision, refuses constant, noise and thick-fog
frames (``out_of_domain: frame gate ...``), and fails safe on a corrupt file, a file for another network or a
gate that cannot score (default action, the reason recorded; exit 2 at the CLI)."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from helpers import TINY_ARCH, bench_system, scene_ids, write_textured_scenes

from assurance.dataio.uavid import read_image, write_sample
from assurance.perturbations import perturb
from el.base.decision import decision_schema
from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig

W, H, WW = 128, 72, 64
SHA = "7e" * 32
DOMAIN = {"height_m": [40, 60], "pitch_deg": [36, 54], "image_width": [64, 7680], "image_height": [36, 4320],
          "aspect": [1.5, 2.0], "perturbations": {"fog": 3}}


def _scenes(root, seeds):
    return write_textured_scenes(root, seeds, W, H)


@pytest.fixture(scope="module")
def setup(tmp_path_factory, one_torch_thread):
    import torch

    from assurance.fitting.frame_gate_fit import GateSettings, fit_gate
    from el.segmentation.architectures import build_model
    from el.segmentation.inference import Segmenter

    root = tmp_path_factory.mktemp("gate")
    train, val = _scenes(root / "train", range(30)), _scenes(root / "val", range(100, 112))
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH), working_width=WW, card={"weights_sha256": SHA}, labels=UAVID)
    doc = fit_gate(train, val, seg, settings=GateSettings(kind="mahalanobis", quantile=0.99), val_scenes="0:6",
                   weights={"path": None, "sha256": SHA, "segmenter": "weights"})
    gate = root / "gate.json"
    gate.write_text(json.dumps(doc))
    return {"seg": seg, "gate": gate, "val": val, "root": root, "doc": doc}


def _system(setup, gate=None):
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", time_budget_s=None,
                         gate=None if gate is None else str(gate))
    return EmergencyLanding(cfg, segmenter=setup["seg"])


def _held_out(setup):
    """Validation scenes not used for the threshold (6-11)."""
    return [read_image(p) for p in sorted(setup["val"].glob("**/Images/*.png"))[6:]]


def test_the_gate_file_records_what_it_was_fitted_and_thresholded_on(setup):
    from el.monitors.frame_gate import load_frame_gate

    b = setup["doc"]["body"]
    assert b["kind"] == "mahalanobis" and b["quantile"] == 0.99 and b["weights"]["sha256"] == SHA
    assert b["params"]["shrinkage"] == 0.1 and len(b["params"]["variance"]) == min(64, b["features"]["dims"])
    assert b["training"]["frames"] == 30 * 11 and b["validation"]["frames"] == 6 * 6
    assert b["validation"]["scenes"] == [0, 6] and len(b["training"]["sha256"]) == 64
    gate = load_frame_gate(setup["gate"])
    stats = setup["seg"].predict_frame(_held_out(setup)[0], stats=True).stats
    assert gate.dims == b["features"]["dims"] == stats.pooled.size  # trunk levels' mean and std
    assert gate.threshold == b["threshold"] and gate.sha256 == setup["doc"]["sha256"]


def test_every_decision_records_the_gate_and_far_frames_take_the_default_action(setup):
    system = _system(setup, setup["gate"])
    held = [system.decide(rgb) for rgb in _held_out(setup)]
    for d in held:
        g = d.input["frame_gate"]
        assert g["kind"] == "mahalanobis" and np.isfinite(g["score"]) and g["threshold"] > 0
        assert json.loads(d.to_json())["input"]["frame_gate"]["score"] == g["score"]
        jsonschema.validate(json.loads(d.to_json()), decision_schema())
    assert sum(d.reason.startswith("out_of_domain") for d in held) <= 1  # held-out in-domain frames pass
    rng = np.random.default_rng(0)
    clean = _held_out(setup)[0]
    far = {"constant": np.full((H, W, 3), 128, np.uint8), "black": np.zeros((H, W, 3), np.uint8),
           "noise": rng.integers(0, 256, (H, W, 3), dtype=np.uint8)}
    _refused(system, far)
    assert _system(setup).decide(clean).input["frame_gate"] is None  # no gate: recorded as none


def _refused(system, frames):
    for name, rgb in frames.items():
        d = system.decide(rgb)
        g = d.input["frame_gate"]
        assert d.action == "default" and g["score"] > g["threshold"], (name, g)
        assert d.reason == (f"out_of_domain: frame gate mahalanobis score {g['score']:.4g} > threshold "
                            f"{g['threshold']:.4g}")
        jsonschema.validate(json.loads(d.to_json()), decision_schema())  # a refusal is a valid decision record


def test_a_gate_fitted_on_clean_frames_refuses_thick_fog(setup, tmp_path):
    """Fitted with fog 1-3 (as fit-gate does), a tiny network's fog 5 looks like the fog it was fitted on, as the
    shipped network's does (docs/results.md): the same file fitted on clean frames refuses it, with constant and
    noise."""
    from el.monitors.frame_gate import frame_gate_document
    from el.monitors.gates import GATES

    seg, gate = setup["seg"], GATES["mahalanobis"]

    def features(frames):
        return np.array([gate.embed(seg.predict_frame(rgb, stats=True).stats) for rgb in frames])

    train = [read_image(p) for p in sorted((setup["root"] / "train").glob("**/Images/*.png"))]
    body = dict(setup["doc"]["body"], params=gate.fit(features(train)))
    body["threshold"] = float(np.quantile(gate.score(body["params"], features(_held_out(setup))), 0.99))
    path = tmp_path / "clean.json"
    path.write_text(json.dumps(frame_gate_document(body)))
    clean = _held_out(setup)[0]
    _refused(_system(setup, path), {"fog5": perturb(clean, "fog", 5, np.random.default_rng(1)),
                                    "constant": np.full((H, W, 3), 200, np.uint8),
                                    "noise": np.random.default_rng(2).integers(0, 256, (H, W, 3), dtype=np.uint8)})


def test_a_bad_gate_file_is_a_fault_and_the_default_action(setup, tmp_path):
    clean = _held_out(setup)[0]
    doc = json.loads(setup["gate"].read_text())
    doc["body"]["threshold"] = 1e9  # altered: its hash no longer matches
    altered = tmp_path / "altered.json"
    altered.write_text(json.dumps(doc))
    other = json.loads(setup["gate"].read_text())
    other["body"]["weights"]["sha256"] = "ab" * 32
    from el.monitors.frame_gate import frame_gate_document

    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps(frame_gate_document(other["body"])))
    truncated = tmp_path / "truncated.json"
    truncated.write_text(setup["gate"].read_text()[:200])
    for path, words in ((altered, "altered"), (foreign, "fitted on network abababababab"),
                        (truncated, "bad JSON"), (tmp_path / "missing.json", "cannot read")):
        d = _system(setup, path).decide(clean)
        assert d.action == "default" and d.reason.startswith("fault: frame_gate: FrameGateError") and words in d.reason
        assert d.input["frame_gate"] is None


def test_a_gate_that_cannot_score_the_frame_fails_safe(setup, monkeypatch):
    from el.segmentation.frame_tap import FramePass

    system = _system(setup, setup["gate"])
    seg, own = system.segmenter, system.segmenter.predict_frame
    # the pass returns no statistics for this frame: the gate cannot judge it
    monkeypatch.setattr(seg, "predict_frame", lambda rgb, *, stats=False: FramePass(own(rgb), None) if stats
                        else own(rgb))
    d = system.decide(_held_out(setup)[0])
    assert d.action == "default" and d.reason.startswith("fault: frame_gate: ValueError: the segmentation pass")
    assert d.input["frame_gate"]["score"] is None and d.input["frame_gate"]["threshold"] > 0


def test_a_network_without_frame_statistics_cannot_carry_a_gate(setup):
    """A plugin network that returns no frame statistics (``FRAME_STATS``) with a gate fitted on its identity: the
    gate is refused when the system is built, and every decision is the default action naming why."""

    class Plain:  # the seam's two methods only, claiming the network the gate was fitted on
        weights_sha256 = SHA

        def __init__(self, seg):
            self.seg = seg

        def predict_frame(self, rgb):
            return self.seg.predict_frame(rgb)

        def predict_patch(self, rgb_patch):
            return self.seg.predict_patch(rgb_patch)

    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", time_budget_s=None, gate=str(setup["gate"]))
    system = EmergencyLanding(cfg, segmenter=Plain(setup["seg"]))
    d = system.decide(_held_out(setup)[0])
    assert system.gate is None and "frame_gate" in system.errors
    assert d.action == "default" and d.reason.startswith("fault: frame_gate: FrameGateError") \
        and "returns no frame statistics" in d.reason and d.input["frame_gate"] is None


def test_cli_fit_gate_and_land_with_it(setup, tmp_path, capsys, monkeypatch):
    import el.segmentation as seg_module
    from assurance.cli import main

    monkeypatch.setattr(seg_module.Segmenter, "load", classmethod(lambda cls, *a, **k: setup["seg"]))
    monkeypatch.chdir(bench_system(tmp_path / "bench").parent)  # the test frames are smaller than the default's 4K
    out = tmp_path / "g.json"
    assert main(["fit-gate", "--data", str(setup["root"] / "train"), "--val", str(setup["val"]), "--out", str(out),
                 "--train-scenes", "0:10", "--val-scenes", "0:4", "--no-progress", "--working-width", str(WW)]) == 0
    text = capsys.readouterr().out
    assert "110 training frames" in text and "24 validation frames" in text and out.is_file()
    image = next(setup["val"].glob("**/Images/*.png"))
    js = tmp_path / "d.json"
    assert main(["land", str(image), "--gate", str(out), "--monitor", "lhd", "--working-width", str(WW),
                 "--json", str(js)]) == 0
    assert "frame gate (mahalanobis): score" in capsys.readouterr().out
    assert json.loads(js.read_text())["input"]["frame_gate"]["threshold"] > 0
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    for gate in (bad, tmp_path / "missing.json"):
        assert main(["land", str(image), "--gate", str(gate), "--monitor", "lhd"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and gate.name in err[0]
    assert main(["fit-gate", "--data", str(setup["root"] / "train"), "--val", str(setup["val"]), "--out",
                 str(out), "--val-scenes", "5:2"]) == 2
    assert "--val-scenes" in capsys.readouterr().err


def test_campaign_readouts_record_the_gate_and_refuse_as_the_flight_code(setup, tmp_path):
    from assurance.campaign.run import CampaignConfig, plan, run_task
    from el.monitors.frame_gate import load_frame_gate

    gate = load_frame_gate(setup["gate"])
    config = CampaignConfig(perturbations=("none", "fog"), severities=(5,), monitors=("lhd",), images=8,
                            core=CoreConfig(working_width=WW), gate={"path": str(setup["gate"]), "sha256": gate.sha256})
    assert config.to_dict()["gate"]["sha256"] == gate.sha256 and "gate" not in CampaignConfig(
        perturbations=("none",)).to_dict()
    clean = [t for t in plan(setup["val"], config) if t.perturbation == "none"]
    rows = [r for t in clean[6:8] for r in run_task(t, config, setup["seg"])["images"]]
    for r in rows:  # scenes 6-7, not used for the threshold
        assert r["fault"] == "" and r["frame_gate_threshold"] == gate.threshold and np.isfinite(r["frame_gate_score"])
        assert r["reason"].startswith("out_of_domain") == (r["frame_gate_score"] > gate.threshold)
    write_sample(tmp_path / "grey", "seq00", "000000", np.full((H, W, 3), 128, np.uint8), scene_ids(W, H), labels=UAVID)
    row = run_task(plan(tmp_path / "grey", config)[0], config, setup["seg"])["images"][0]
    assert row["action"] == "default" and row["reason"].startswith("out_of_domain: frame gate mahalanobis score")
    assert row["h_decision"] == row["h_default"] and row["frame_gate_score"] > gate.threshold
    import pandas as pd

    from assurance.evidence.domain_section import odd_rows

    man = {"config": {"odd": DOMAIN, "core": {"pose": {"height_m": 50.0, "pitch_deg": 45.0}}}}
    shown = {r["name"]: r for r in odd_rows(man, pd.DataFrame([*rows, row]), {"height": 0.2, "pitch": 0.2})}
    assert shown["Frame gate"]["evidence"] == "frames refused: none: 1"  # the grey frame, per perturbation
    assert f"{gate.threshold:.4g}" in shown["Frame gate"]["declared"]
    plain = CampaignConfig(perturbations=("none",), monitors=("lhd",), images=1, core=CoreConfig(working_width=WW))
    row = run_task(plan(setup["val"], plain)[0], plain, setup["seg"])["images"][0]
    assert np.isnan(row["frame_gate_score"]) and np.isnan(row["frame_gate_threshold"])  # no gate: NaN, not 0
    changed = CampaignConfig(perturbations=("none",), monitors=("lhd",), images=1, core=CoreConfig(working_width=WW),
                             gate={"path": str(setup["gate"]), "sha256": "0" * 64})
    row = run_task(plan(setup["val"], changed)[0], changed, setup["seg"])["images"][0]
    assert "frame gate changed since the run recorded it" in row["fault"]


def test_which_gate_a_command_deploys(tmp_path, monkeypatch):
    import argparse

    import el.flight.pipeline
    from assurance.cli.system_options import assessed
    from assurance.system.find import load_system

    shipped = tmp_path / "shipped.json"
    monkeypatch.setattr(el.flight.pipeline, "DEPLOYED_GATE", shipped)

    def args(**kw):
        return argparse.Namespace(**{"gate": None, "weights": None, "system_file": None, **kw})

    def frame_gate_path(namespace):
        return assessed(namespace).gate

    assert frame_gate_path(args()) == shipped  # the shipped network: the shipped gate
    assert frame_gate_path(args(weights="mine.pt")) is None  # another network: its own gate, or none
    assert frame_gate_path(args(gate="none")) is None and frame_gate_path(args(gate="g.json")) == Path("g.json")
    toml = tmp_path / "uav-el.toml"
    toml.write_text('format = "uav-el-system/1"\n[monitor]\ngate = "none"\n')
    assert frame_gate_path(args(system_file=load_system(toml))) is None
    monkeypatch.setattr(el.flight.pipeline, "DEPLOYED_GATE", None)
    assert frame_gate_path(args()) is None


def test_the_shipped_gate_is_bound_to_the_shipped_network_and_deployed():
    import el.flight.pipeline
    from el.monitors.frame_gate import load_frame_gate

    shipped = Path(el.__file__).parent / "monitors" / "data" / "frame_gate.json"
    # fitted on 3840x2160 frames, the camera's (docs/results.md)
    assert el.flight.pipeline.DEPLOYED_GATE == shipped.resolve()
    gate = load_frame_gate(shipped)
    card = json.loads((shipped.parents[2] / "segmentation" / "weights" / "model.json").read_text())
    assert gate.network_sha256 == card["weights_sha256"] and gate.kind == "mahalanobis"
    b = gate.body  # chosen on validation only: fitted on train, thresholded on validation scenes 0-34
    assert b["training"]["path"].endswith("train") and b["validation"]["path"].endswith("val")
    assert b["validation"]["scenes"] == [0, 35] and b["quantile"] == 0.997 and gate.dims == 448
    assert b["training"]["frames"] == 2200 and b["training"]["path"].endswith("gate4k/train")
    assert shipped.stat().st_size < 1_000_000


def test_sweep_replays_a_frame_gate_and_gate_check_scores_other_scenes(setup):
    from assurance.analysis.ood_replay import gate_score, load_gate
    from assurance.fitting.gate_check import check
    from el.monitors.frame_gate import FrameGate

    gate = load_gate(setup["gate"])
    assert isinstance(gate, FrameGate)
    grey = np.full((H, W, 3), 128, np.uint8)
    assert gate_score(gate, setup["seg"], grey) > gate.threshold
    rows = check(setup["gate"], setup["val"], setup["seg"])
    assert set(rows) == {"none:0", "brightness:3", "fog:3", "motion_blur:3", "shifted_pixels:3", "pixel_trap:3"}
    assert all(r["frames"] == 12 and 0 <= r["flagged"] <= 12 and r["max"] >= r["median"] for r in rows.values())
    assert rows["none:0"]["flagged"] <= 1  # 6 of its 12 clean scenes set the threshold


def test_the_kernel_parts_bind_the_gate_to_their_network(setup):
    """``el.flight.kernel.build_parts``, the one maker of the kernel's parts (flight, campaign, ground truth), binds a
    gate
    to the network: kept for the network it was fitted on, refused for another."""
    from helpers import OracleSegmenter

    from el.base.errors import FrameGateError
    from el.flight.kernel import build_parts
    from el.monitors.frame_gate import load_frame_gate

    gate = load_frame_gate(setup["gate"])
    parts = build_parts(setup["seg"], CoreConfig(working_width=WW), gate=gate)
    assert parts.gate is gate and parts.labels == UAVID and parts.fault is None
    with pytest.raises(FrameGateError, match="fitted on network"):
        build_parts(OracleSegmenter(WW), CoreConfig(working_width=WW), gate=gate)
