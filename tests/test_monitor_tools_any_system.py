"""Every monitor tool for any system: a user's own ONNX network (6 classes mapped onto the 23
semantic_drone classes) gets a frame gate fitted on its output (``uav-el fit-gate``) that then runs in flight and in
a campaign; a campaign's presets leave out what the network cannot run (MC dropout) with a printed reason, refuse it
when asked for, and run every scene of the data unless told otherwise; a configuration failing on a task keeps the
other configurations' readouts of that task; ``fit-monitor`` reads the truth in the system's palette and names its
features after the system's classes."""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import TINY_ARCH, OracleSegmenter, nearest_class, scene_ids

from assurance import cli
from assurance.dataio.uavid import write_sample
from el.classes.labels import CLASS_IDS, UAVID, ids_to_colors, load_label_set
from el.geometry.config import CoreConfig

EXAMPLE_LABELS = Path(__file__).resolve().parents[1] / "examples" / "my-drone" / "labels.yaml"
TO_CITY_SURVEY = {"road": "asphalt", "low_vegetation": "lawn", "building": "house", "moving_car": "driving_vehicle",
                  "human": "pedestrian", "tree": "canopy", "static_car": "parked_vehicle", "clutter": "misc"}
CLASSES = ["ground", "lawn", "street", "building", "person", "water"]
TO_DRONE = {"ground": "dirt", "lawn": "grass", "street": "paved-area", "building": "roof", "person": "person",
            "water": "water"}
DRONE = load_label_set("semantic_drone")
UNREACHABLE = [n for n in DRONE.names if n not in TO_DRONE.values()]
W, H = 320, 180


# -- a user's ONNX network on semantic_drone -------------------------------------------------------------------
def _export_unet(path: Path) -> Path:
    """A 2-layer conv net with 6 output channels, exported with plain torch.onnx.export (no project metadata, no
    trunk outputs): the logits are all a frame gate can read."""
    onnx = pytest.importorskip("onnx")
    torch = pytest.importorskip("torch")
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 8, 3, padding=1), torch.nn.ReLU(), torch.nn.Conv2d(8, 6, 1)).eval()
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(net, (torch.rand(1, 3, 32, 48),), buf, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {2: "h", 3: "w"}}, opset_version=17, dynamo=False)
    path.write_bytes(onnx.load_from_string(buf.getvalue()).SerializeToString())
    return path


def _drone_scenes(root: Path, seeds) -> Path:
    """Textured scenes labelled in the semantic_drone palette (grass with a paved strip and a roof)."""
    for i, seed in enumerate(seeds):
        rng = np.random.default_rng(seed)
        ids = np.full((H, W), DRONE.ids["grass"], np.uint8)
        c = int(rng.integers(20, W - 40))
        ids[:, c:c + 12] = DRONE.ids["paved-area"]
        ids[: H // 3, (c + 120) % (W - 40):(c + 120) % (W - 40) + 30] = DRONE.ids["roof"]
        rgb = DRONE.ids_to_colors(ids).astype(np.int16) + rng.integers(-12, 13, (H, W, 3))
        write_sample(root, "seq00", f"{i:06d}", np.clip(rgb, 0, 255).astype(np.uint8), ids, labels=DRONE)
    return root


def _system_file(folder: Path, *, gate: str | None = None) -> Path:
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_DRONE.items())
    text = (f'format = "uav-el-system/1"\n[labels]\npreset = "semantic_drone"\n'
            f'[model]\npath = "unet.onnx"\nworking_width = 160\nclass_map = {{ {class_map} }}\n'
            f'unreachable = {json.dumps(UNREACHABLE)}\n'
            f'[model.onnx]\nclass_names = {json.dumps(CLASSES)}\n'
            '[odd]\nheight_m = [40.0, 60.0]\npitch_deg = [36.0, 54.0]\nimage_width = [300, 400]\n'
            'image_height = [150, 200]\naspect = [1.5, 2.0]\n'
            '[monitor]\nspec = "lhd"\n' + (f'gate = "{gate}"\n' if gate else ""))
    path = folder / ("uav-el-gated.toml" if gate else "uav-el.toml")
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    pytest.importorskip("onnxruntime")
    root = tmp_path_factory.mktemp("user")
    _export_unet(root / "unet.onnx")
    return {"root": root, "system": _system_file(root), "train": _drone_scenes(root / "train", range(3)),
            "val": _drone_scenes(root / "val", range(10, 12)), "test": _drone_scenes(root / "test", range(20, 23))}


@pytest.fixture(scope="module")
def gated(user):
    """``uav-el fit-gate`` on the user's system: it must fit (it exited 70 on the class-mapped network)."""
    gate = user["root"] / "gate.json"
    code = cli.main(["fit-gate", "--system", str(user["system"]), "--data", str(user["train"]), "--val",
                     str(user["val"]), "--out", str(gate), "--quantile", "0.9", "--no-progress"])
    assert code == 0
    return {**user, "gate": gate, "gated": _system_file(user["root"], gate=gate.name)}


def test_fit_gate_fits_on_a_class_mapped_onnx_networks_output(gated):
    from assurance.system import load_system
    from assurance.system.system import System
    from el.base.hashing import sha256_file
    from el.monitors.frame_gate import load_frame_gate

    gate = load_frame_gate(gated["gate"])
    assert gate.features == "output" and gate.dims == 2 * len(CLASSES)  # the network's own 6 logits, mean and std
    assert gate.network_sha256 == sha256_file(gated["root"] / "unet.onnx")
    seg = System.build(load_system(gated["system"])).segmenter()
    assert not hasattr(seg.network, "model") and seg.frame_stats  # an ONNX file: no trunk, its statistics returned
    probs, stats = seg.predict_frame(np.zeros((H, W, 3), np.uint8), stats=True)
    assert probs.shape[0] == seg.labels.num_classes and stats.pooled is None
    assert np.isfinite(gate.score(stats))


def test_the_fitted_gate_runs_in_flight_and_in_the_campaign(gated, tmp_path, capsys):
    from assurance.campaign import readouts
    from assurance.dataio.uavid import read_image
    from assurance.system import load_system
    from assurance.system.system import System
    from el.flight.pipeline import EmergencyLanding

    system = System.build(load_system(gated["gated"]))
    assert system.gate == gated["gate"]
    landing = EmergencyLanding(system.flight_config(), segmenter=system.segmenter())
    assert landing.fault is None, landing.fault
    frame = read_image(next((gated["test"] / "seq00").glob("Images/*.png")))
    d = landing.decide(frame)
    assert not d.reason.startswith("fault"), d.reason
    assert np.isfinite(d.input["frame_gate"]["score"]) and d.input["frame_gate"]["sha256"]
    out = tmp_path / "decision.json"
    image = next((gated["test"] / "seq00").glob("Images/*.png"))
    assert cli.main(["land", str(image), "--system", str(gated["gated"]), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["input"]["frame_gate"]["score"] is not None
    run = tmp_path / "run"
    assert cli.main(["campaign", "--system", str(gated["gated"]), "--data", str(gated["test"]), "--out", str(run),
                     "--perturbations", "none", "--monitors", "lhd", "--quiet"]) == 0
    man = readouts.read_manifest(run)
    assert man["config"]["gate"]["path"] == str(gated["gate"]) and man["config"]["monitors"] == ["lhd"]
    images = readouts.load_table(run, "images")
    assert (images["fault"] == "").all(), images["fault"].tolist()
    assert np.isfinite(images["frame_gate_score"]).all() and len(images) == 3


def test_presets_leave_out_mcd_with_a_reason_and_refuse_it_when_asked(user, tmp_path, capsys):
    from assurance.campaign import readouts

    run = tmp_path / "run"
    assert cli.main(["campaign", "--system", str(user["system"]), "--data", str(user["test"]), "--out", str(run),
                     "--perturbations", "none", "--quiet"]) == 0  # the demo preset
    out = capsys.readouterr().err  # notes on what is not evaluated: stderr, shown under --quiet too
    left = [line for line in out.splitlines() if line.startswith("uav-el campaign: left out")]
    assert any("'lhd+mcd:n=10,rho=0.9'" in line and "MC dropout" in line for line in left), out
    assert all(str(user["system"]) in line and "MappedModel" not in line for line in left), left
    monitors = readouts.read_manifest(run)["config"]["monitors"]
    assert monitors[0] == "lhd" and not any("mcd" in m for m in monitors)  # the deployed one first, no MCD
    assert readouts.read_manifest(run)["config"].get("images") is None  # every scene of the data
    assert readouts.load_table(run, "images")["key"].nunique() == 3
    assert "evaluating the first" not in out
    code = cli.main(["campaign", "--system", str(user["system"]), "--data", str(user["test"]), "--out",
                     str(tmp_path / "asked"), "--perturbations", "none", "--monitors", "lhd", "lhd+mcd:n=10,rho=0.9",
                     "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "'lhd+mcd:n=10,rho=0.9'" in err[0] and str(user["system"]) in err[0] and "MappedModel" not in err[0]
    assert not (tmp_path / "asked").exists()  # refused before any task
    assert cli.main(["campaign", "--system", str(user["system"]), "--data", str(user["test"]), "--out",
                     str(tmp_path / "cut"), "--perturbations", "none", "--monitors", "lhd", "--images", "2",
                     "--quiet"]) == 0
    assert "evaluating the first 2 of the 3 scenes" in capsys.readouterr().err


def test_a_system_naming_only_a_card_deploys_the_cards_monitor_with_its_gate(gated, tmp_path):
    """The deployed parts of a user's system reach the campaign: the card's calibrated monitor (first, bound to the
    user's network) and the frame gate, from the system file alone."""
    from assurance.campaign import readouts
    from assurance.fitting.calibration import ThresholdRule, calibration_body
    from el.base.hashing import sha256_file
    from el.monitors.calibration import card_document

    network = {"path": "unet.onnx", "sha256": sha256_file(gated["root"] / "unet.onnx"), "segmenter": "weights"}
    rng = np.random.default_rng(0)
    body = calibration_body(rng.random(300), rng.random(300) < 0.5, monitor="lhd",
                            rule=ThresholdRule(miss_rate=0.5, confidence=0.5),
                            split={"path": "val", "images": 3, "sha256": "0" * 64, "perturbation": "none"},
                            weights=network)
    (gated["root"] / "card.json").write_text(json.dumps(card_document(body)))
    text = gated["gated"].read_text().replace('spec = "lhd"\n', 'calibration = "card.json"\n')
    system = gated["root"] / "uav-el-card.toml"
    system.write_text(text)
    run = tmp_path / "run"
    assert cli.main(["campaign", "--system", str(system), "--data", str(gated["test"]), "--out", str(run),
                     "--perturbations", "none", "--quiet"]) == 0
    cfg = readouts.read_manifest(run)["config"]
    assert cfg["monitors"][0] == body["spec"] and cfg["gate"]["path"] == str(gated["gate"])
    images = readouts.load_table(run, "images")
    assert np.isfinite(images[images["monitor"] == body["spec"]]["frame_gate_score"]).all()


def test_campaign_monitors_check_each_configuration_once():
    from assurance.campaign.presets import MonitorSupportError, campaign_monitors, monitor_support

    class NoDropout:
        """A network without MC dropout (frames and patches only)."""

        weights_sha256 = "0f" * 32

        def predict_frame(self, rgb):
            raise AssertionError("nothing is judged by the support check")

        predict_patch = predict_frame

    model = NoDropout()
    assert monitor_support("lhd", model) is None and "MC dropout" in monitor_support("lhd+mcd:n=10,rho=0.9", model)
    choice = campaign_monitors("demo", deployed="lhd", model=model)
    assert choice.monitors == ("lhd", "lhd+ch:tau=0.25")
    assert campaign_monitors("demo", deployed="none", model=model).monitors == ("lhd", "lhd+ch:tau=0.25")
    assert [n for n, _ in choice.left_out] == ["lhd+mcd:n=10,rho=0.9", "lhd+ch+mcd:tau=0.25,n=10,rho=0.9"]
    with pytest.raises(MonitorSupportError, match="lhd\\+mcd.*uav-el.toml"):
        campaign_monitors("demo", given=["lhd", "lhd+mcd:n=10,rho=0.9"], model=model, where="uav-el.toml")
    with pytest.raises(MonitorSupportError, match="'lhd\\+mcd:n=10,rho=0.9'"):  # the deployed one is never dropped
        campaign_monitors("demo", deployed="lhd+mcd:n=10,rho=0.9", model=model)
    # the shipped system's presets are unchanged: the deployed configuration first, then the headline grid
    from el.flight.pipeline import PipelineConfig
    from el.monitors import DEMO_GRID

    assert campaign_monitors("release").monitors == (PipelineConfig().monitor_name, *DEMO_GRID)


# -- a failing configuration keeps the others' readouts ------------------------------------------------------
@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    from helpers import write_textured_scenes

    return write_textured_scenes(tmp_path_factory.mktemp("scenes") / "data", range(3))


def test_a_failing_configuration_keeps_the_other_configurations_readouts(scenes, monkeypatch):
    from assurance.campaign.run import CampaignConfig, plan, run_task
    from el.monitors import CHMonitor

    core = CoreConfig(working_width=64)
    both = CampaignConfig(perturbations=("none",), monitors=("lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=3,rho=0.9"),
                          core=core)
    alone = CampaignConfig(perturbations=("none",), monitors=("lhd", "lhd+mcd:n=3,rho=0.9"), core=core)
    seg = OracleSegmenter(64)
    expected = [run_task(t, alone, seg) for t in plan(scenes, alone)]

    def boom(self, reduced):
        raise RuntimeError("the class hierarchy broke")

    monkeypatch.setattr(CHMonitor, "judge", boom)
    judged = 0
    for task, want in zip(plan(scenes, both), expected, strict=True):
        rows = run_task(task, both, seg)
        by = {r["monitor"]: r for r in rows["images"]}
        assert set(by) == set(both.monitors)
        assert by["lhd+ch:tau=0.25"]["fault"] == "RuntimeError: the class hierarchy broke"
        assert not any(c["monitor"] == "lhd+ch:tau=0.25" for c in rows["candidates"])
        for name in alone.monitors:
            got, ref = by[name], next(r for r in want["images"] if r["monitor"] == name)
            assert got["fault"] == "" and (got["action"], got["selected"], got["reason"]) == (
                ref["action"], ref["selected"], ref["reason"])
            mine = [(c["rank"], c["accepted"], c["score"]) for c in rows["candidates"] if c["monitor"] == name]
            assert mine == [(c["rank"], c["accepted"], c["score"]) for c in want["candidates"]
                            if c["monitor"] == name]
            judged += len(mine)
    assert judged > 0  # there were candidates to judge


def test_a_configuration_that_cannot_be_built_faults_alone(scenes, monkeypatch):
    from assurance.campaign import task as task_module
    from assurance.campaign.run import CampaignConfig, plan, run_task

    real = task_module.build_monitor

    def build(name, **kwargs):
        if name.startswith("lhd+ch"):
            raise ValueError("a class hierarchy supports at most 16 classes")
        return real(name, **kwargs)

    monkeypatch.setattr(task_module, "build_monitor", build)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd", "lhd+ch:tau=0.25"),
                            core=CoreConfig(working_width=64))
    rows = run_task(plan(scenes, config)[0], config, OracleSegmenter(64))
    by = {r["monitor"]: r for r in rows["images"]}
    assert by["lhd+ch:tau=0.25"]["fault"].startswith("ValueError: a class hierarchy")
    assert by["lhd"]["fault"] == "" and by["lhd"]["action"] in ("land", "default")


# -- fit-monitor in the system's palette -------------------------------------------------------------------------
class RoadBlindFrame(OracleSegmenter):
    """Frames: road seen as low vegetation (candidates land on roads); patches: perfect (UAVid classes)."""

    def predict_frame(self, rgb):
        ids = nearest_class(rgb)
        ids[ids == CLASS_IDS["road"]] = CLASS_IDS["low_vegetation"]
        return super().predict_frame(ids_to_colors(ids))


def _learned_split(root: Path, n: int, offset: int, labels) -> Path:
    """Scenes whose images are UAVid-coloured (what the UAVid network reads) and whose label maps are in
    ``labels``' palette (UAVid, or the renamed and recoloured city_survey)."""
    for i in range(n):
        ids = scene_ids(256, 144, seed=offset + i, road_col=20 + 40 * i)
        ids[:, 140 + 12 * i: 160 + 12 * i] = CLASS_IDS["road"]
        mine = ids if labels == UAVID else np.array([labels.ids[TO_CITY_SURVEY[n]] for n in UAVID.names],
                                                    np.uint8)[ids]
        write_sample(root, "seq00", f"{i:06d}", ids_to_colors(ids), mine, labels=labels)
    return root


def test_fit_monitor_reads_the_truth_in_the_systems_palette(tmp_path):
    from assurance.fitting.learned_monitor import FeatureSettings, collect_candidates, fit_learned_monitor
    from el.monitors import build_monitor
    from el.monitors.learned import base_features, load_learned_model
    from el.segmentation.class_map import MappedModel

    city = load_label_set(EXAMPLE_LABELS)
    core = CoreConfig(working_width=256)
    net = RoadBlindFrame(256)
    mapped = MappedModel(net, TO_CITY_SURVEY, city)
    uavid = collect_candidates(_learned_split(tmp_path / "u", 4, 0, UAVID), net, features=FeatureSettings(core=core))
    mine = collect_candidates(_learned_split(tmp_path / "c", 4, 0, city), mapped, features=FeatureSettings(core=core))
    assert uavid.y.sum() > 0 and (uavid.y == mine.y).all()  # the same candidates are truly unsafe
    names_u, names_c = base_features(UAVID), base_features(city)
    assert "hd_max_p_asphalt" in names_c and "hd_max_p_road" not in names_c
    rename = {f"{p}{u}": f"{p}{TO_CITY_SURVEY[u]}" for u in UAVID.names for p in ("hd_max_p_", "lr_max_p_")}
    columns = [names_c.index(rename.get(n, n)) for n in names_u]
    np.testing.assert_allclose(mine.x[:, columns], uavid.x, atol=1e-6)  # each class's feature, renamed
    doc = fit_learned_monitor(tmp_path / "c" / "", mapped, val=_learned_split(tmp_path / "cv", 4, 100, city),
                              features=FeatureSettings(core=core))
    assert doc["body"]["labels"] == "city_survey" and doc["body"]["features"] == list(names_c)
    path = tmp_path / "learned.json"
    path.write_text(json.dumps(doc))
    assert load_learned_model(path, labels=city).threshold == doc["body"]["threshold"]
    monitor = build_monitor(f"learned:model={path}", labels=city)
    monitor.check_network(mapped)  # bound to the network the class map wraps


def test_fit_monitor_refuses_mcd_features_on_a_network_without_dropout(user, tmp_path, capsys):
    code = cli.main(["fit-monitor", "--system", str(user["system"]), "--data", str(user["train"]), "--val",
                     str(user["val"]), "--out", str(tmp_path / "m.json"), "--mcd", "5", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--mcd 5" in err[0] and str(user["system"]) in err[0], err


# -- the class map passes the frame pass's statistics through ----------------------------------------------------
def test_a_class_mapped_torch_network_keeps_its_trunk_statistics(one_torch_thread):
    import torch

    from el.base.errors import FrameGateError
    from el.monitors.frame_gate import check_frame_stats
    from el.segmentation.architectures import build_model
    from el.segmentation.class_map import MappedModel
    from el.segmentation.inference import Segmenter

    city = load_label_set(EXAMPLE_LABELS)
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH), working_width=64, card={"weights_sha256": "7e" * 32}, labels=UAVID)
    mapped = MappedModel(seg, TO_CITY_SURVEY, city)
    assert mapped.network_classes == 8 and mapped.frame_stats is True
    rgb = ids_to_colors(scene_ids(128, 72))
    probs, tap = mapped.predict_frame(rgb, stats=True)
    own = seg.predict_frame(rgb, stats=True).stats  # the network's own statistics, in its own classes
    assert probs.shape[0] == city.num_classes and np.array_equal(probs, mapped.predict_frame(rgb))
    assert tap.pooled is not None and tap.output.shape == (2 * UAVID.num_classes,)
    assert np.array_equal(tap.output, own.output) and np.array_equal(tap.pooled, own.pooled)

    class Plain(OracleSegmenter):
        pass

    bare = MappedModel(Plain(64), TO_CITY_SURVEY, city)
    assert bare.frame_stats is False and bare.predict_frame(rgb, stats=True).stats is None  # nothing to pass on
    with pytest.raises(FrameGateError, match="returns no frame statistics"):  # so a gate is refused
        check_frame_stats(bare, "gate.json")
