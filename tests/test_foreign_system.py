"""A system that shares nothing with the shipped one, end to end on tiny data, without editing the package: a
network of its own (6 classes, exported with plain ``torch.onnx.export``, no project metadata, ImageNet mean/std),
mapped onto the Semantic Drone Dataset's 23 classes, a nadir camera (23.5 mm sensor, 16 mm lens) with per-frame
poses, scenes in that palette. ``land``, ``fit-monitor``, ``fit-gate``, ``calibrate``, a campaign, ``verify`` and
``evidence`` all work; the default area is the ground below the drone (the frame's centre); the report is about this
system and nothing of the shipped one. The walkthrough in docs/certify.md runs these steps."""

import json
import re
from pathlib import Path

import pytest

from assurance import cli

pytest.importorskip("onnxruntime")
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

NET_CLASSES = ["ground", "plants", "pavement", "house", "vehicle", "human"]
CLASS_MAP = {"ground": "gravel", "plants": "grass", "pavement": "paved-area", "house": "roof", "vehicle": "car",
             "human": "person"}
UAVID_TO_DRONE = {"road": "paved-area", "building": "roof", "static_car": "car", "moving_car": "car", "tree": "tree",
                  "low_vegetation": "grass", "human": "person", "clutter": "gravel"}
SIZE = (320, 240)


def export_network(path: Path, data: Path) -> None:
    """A small fully convolutional network of 6 classes, trained briefly on the user's own training scenes and
    exported as a user would (plain ``torch.onnx.export``: no metadata of ours)."""
    import numpy as np
    import torch
    from PIL import Image

    from el.classes.labels import load_label_set

    drone = load_label_set("semantic_drone")
    lut = np.zeros(256, dtype=np.int64)  # system class id -> network class (unmapped ones: ground)
    for net_class, name in CLASS_MAP.items():
        lut[drone.names.index(name)] = NET_CLASSES.index(net_class)
    lut[drone.names.index("tree")] = NET_CLASSES.index("plants")
    xs, ys = [], []
    for img in sorted(data.glob("seq*/Images/*.png")):
        rgb = np.asarray(Image.open(img).convert("RGB"), dtype=np.float32) / 255.0
        ids = drone.colors_to_ids(np.asarray(Image.open(img.parents[1] / "Labels" / img.name).convert("RGB")))
        xs.append((rgb - [0.485, 0.456, 0.406]) / [0.229, 0.224, 0.225])
        ys.append(lut[np.minimum(ids, 255)])
    x = torch.tensor(np.stack(xs), dtype=torch.float32).permute(0, 3, 1, 2)
    y = torch.tensor(np.stack(ys))
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 16, 3, padding=1), torch.nn.ReLU(),
                              torch.nn.Conv2d(16, 16, 3, padding=1), torch.nn.ReLU(),
                              torch.nn.Conv2d(16, len(NET_CLASSES), 1))
    opt = torch.optim.Adam(net.parameters(), lr=0.02)
    for _ in range(25):
        opt.zero_grad()
        torch.nn.functional.cross_entropy(net(x), y).backward()
        opt.step()
    net.eval()
    torch.onnx.export(net, torch.zeros(1, 3, 64, 64), str(path), input_names=["image"], output_names=["logits"],
                      dynamic_axes={"image": {2: "h", 3: "w"}, "logits": {2: "h", 3: "w"}}, dynamo=False)


def system_text(gate: str | None = None) -> str:
    from el.classes.labels import load_label_set

    drone = load_label_set("semantic_drone")
    unreachable = [n for n in drone.names if n not in CLASS_MAP.values()]
    lines = [
        'format = "uav-el-system/1"',
        "[system]", 'name = "survey-nadir: a network of its own over the Semantic Drone classes"',
        "[model]", 'path = "net.onnx"', f"class_map = {_inline(CLASS_MAP)}", f"unreachable = {json.dumps(unreachable)}",
        "[model.onnx]", f"class_names = {json.dumps(NET_CLASSES)}", "mean = [0.485, 0.456, 0.406]",
        "std = [0.229, 0.224, 0.225]",
        "[model.provenance]", 'trained_by = "Example Survey Ltd."', 'training_data = "data/train"',
        'validation_data = "data/val"',
        "[camera]", 'name = "nadir-cam"', "sensor_width_mm = 23.5", "focal_mm = 16.0",
        f"image_width = {SIZE[0]}", f"image_height = {SIZE[1]}", "height_m = 20.0", "pitch_deg = 90.0",
        'poses = "required"',
        "[odd]", "height_m = [10.0, 35.0]", "pitch_deg = [85.0, 90.0]",
        "[labels]", 'preset = "semantic_drone"',
        "[monitor]", 'spec = "lhd"'] + ([f'gate = "{gate}"'] if gate else []) + [
        "[data]", 'train = "data/train"', 'val = "data/val"', 'test = "data/test"',
    ]
    return "\n".join(lines) + "\n"


def _inline(mapping: dict[str, str]) -> str:
    return "{ " + ", ".join(f'"{k}" = "{v}"' for k, v in mapping.items()) + " }"


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    root = tmp_path_factory.mktemp("foreign")
    for split, scenes in (("train", 8), ("val", 4), ("test", 3)):
        assert cli.main(["synth", "--out", str(root / "src" / split), "--scenes", str(scenes), "--split", split,
                         "--size", f"{SIZE[0]}x{SIZE[1]}", "--sensor-width", "23.5", "--hfov", "72.6",
                         "--heights", "15:30", "--pitches", "90:90", "--no-progress"]) == 0
        assert cli.main(["recolour", "--data", str(root / "src" / split), "--out", str(root / "data" / split),
                         "--to", "semantic_drone", "--map", json.dumps(UAVID_TO_DRONE)]) == 0
    export_network(root / "net.onnx", root / "data" / "train")
    system = root / "uav-el.toml"
    system.write_text(system_text())
    return {"root": root, "system": system}


def test_land_decides_at_the_nadir_point(foreign, tmp_path):
    out = tmp_path / "decision.json"
    image = foreign["root"] / "data" / "test" / "seq00" / "Images" / "000000.png"
    assert cli.main(["land", str(image), "--system", str(foreign["system"]), "--json", str(out)]) == 2  # no pose
    assert cli.main(["land", str(image), "--system", str(foreign["system"]), "--height", "20", "--pitch", "90",
                     "--json", str(out)]) == 0
    decision = json.loads(out.read_text())
    assert not str(decision.get("reason") or "").startswith("fault"), decision.get("reason")
    area = decision["default_area"]
    assert abs(area["x"] - SIZE[0] / 2) < 1 and abs(area["y"] - SIZE[1] / 2) < 1  # the ground below the drone
    labels = image.parents[1] / "Labels" / image.name  # the ground truth, drawn in its own palette
    assert cli.main(["land", "--labels", str(labels), "--system", str(foreign["system"]), "--height", "20",
                     "--pitch", "90", "--overlay", str(tmp_path / "overlay.png")]) == 0


def test_monitor_tools_campaign_and_report_are_about_this_system(foreign, tmp_path):
    root, system = foreign["root"], foreign["system"]
    main = cli.main
    assert main(["fit-monitor", "--system", str(system), "--out", str(root / "monitor.json")]) == 0
    assert main(["fit-gate", "--system", str(system), "--out", str(root / "gate.json"), "--no-progress"]) == 0
    system.write_text(system_text(gate="gate.json"))
    assert main(["calibrate", "--system", str(system), "--data", str(root / "data" / "val"), "--monitor", "msp",
                 "--miss-rate", "0.5", "--confidence", "0.5", "--out", str(root / "card.json")]) == 0  # tiny data
    run = root / "runs" / "foreign"
    assert main(["campaign", "--system", str(system), "--out", str(run), "--perturbations", "none", "fog",
                 "--monitors", "lhd", "lhd+ch:tau=0.25", "msp", f"learned:model={root / 'monitor.json'}",
                 "--quiet"]) == 0
    from assurance.campaign import readouts

    images = readouts.load_table(run, "images")
    assert (images["fault"].fillna("") == "").all(), images["fault"].tolist()
    assert len(images) == 3 * 2 * 4  # every frame, perturbation and configuration
    man = json.loads((run / "manifest.json").read_text())
    assert man["config"].get("gate"), "the campaign ran the system's frame gate"
    report = tmp_path / "report"
    main(["verify", str(run), "--out", str(report), "--system", str(system), "-k", "not rerun"])
    from assurance import requirements as rq

    rerun = rq.check_rerun(run, work_dir=tmp_path / "rerun")  # EL-R11 re-plans with the run's own classes
    assert rerun.status == rq.PASS, rerun.message()
    main(["evidence", "--system", str(system), "--run", str(run), "--out", str(report), "--no-pdf", "--boot", "50"])
    from el.base.hashing import sha256_file

    html = (report / "evidence.html").read_text()
    assert sha256_file(root / "net.onnx") in html
    for shipped in ("Phantom 4", "45 degrees", "0d3dab88", "el/monitors/data", "road, car or building",
                    "make release-evidence"):
        assert shipped not in html, shipped
    assert not re.search(r"(?<![\d.])50 m\b", html)
    assert "paved-area" in html and "roof" in html  # its forbidden classes, by name
    record = json.loads((report / "evidence.json").read_text())["data_record"]
    assert {"network training", "network validation"} <= {d["role"] for d in record["datasets"]}
    fitted = [d for d in record["datasets"] if d["role"].startswith("learned monitor")]
    assert len(fitted) == 2 and all(d["folder"] and not d["unread"] for d in fitted), fitted  # found from any folder
    shared = [c for c in record["disjoint"] if c["check"].startswith("no scene or image shared")]
    assert shared and all(c["result"] == "pass" for c in shared), shared  # its declared training data
