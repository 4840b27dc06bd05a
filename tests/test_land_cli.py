"""``uav-el land`` (ground-truth pipeline) in-process: outputs, overlay, and bad input as one-line errors."""

import json

import cv2
import jsonschema
import numpy as np
import pytest
from helpers import bench_system

from assurance import cli
from assurance.dataio.uavid import read_image, write_image, write_labels
from assurance.evidence.overlay import STATUS_COLOURS, draw_decision
from el.base.decision import Candidate, Decision, Disc, MonitorVerdict, decision_schema
from el.classes.labels import CLASS_IDS, UAVID

W, H = 256, 144


@pytest.fixture
def main(monkeypatch, tmp_path):
    """``uav-el`` with only the ``land`` command, so these tests do not depend on the others, run where a system
    file admits their small frames (the embedded default declares only 4K frames)."""
    monkeypatch.setattr(cli, "COMMANDS", {"land": "land"})
    monkeypatch.chdir(bench_system(tmp_path / "bench").parent)
    return cli.main


@pytest.fixture
def scene(tmp_path):
    ids = np.full((H, W), CLASS_IDS["low_vegetation"], dtype=np.uint8)
    ids[70:74, :] = CLASS_IDS["road"]
    ids[90:120, 20:60] = CLASS_IDS["building"]
    ids[40:60, 150:200] = CLASS_IDS["tree"]
    labels = tmp_path / "labels.png"
    image = tmp_path / "image.png"
    write_labels(labels, ids, labels=UAVID)
    write_image(image, np.full((H, W, 3), 120, dtype=np.uint8))
    return labels, image


def one_line_error(capsys, *needles):
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# -- the happy path ------------------------------------------------------------------------------------
@pytest.mark.requirements("EL-R01")
def test_land_writes_a_schema_valid_decision_and_an_overlay(main, scene, tmp_path, capsys):
    labels, image = scene
    out_json, out_png = tmp_path / "out" / "d.json", tmp_path / "o.png"
    rc = main(["land", "--labels", str(labels), "--image", str(image), "--json", str(out_json),
               "--overlay", str(out_png), "--working-width", "128"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "decision: LAND on candidate #0" in printed
    d = json.loads(out_json.read_text())
    jsonschema.validate(d, decision_schema())
    assert d["action"] == "land" and d["selected"] == 0 and d["reason"] == "accepted"
    assert d["input"]["path"] == str(labels) and d["input"]["width"] == W and d["input"]["height"] == H
    assert len(d["input"]["sha256"]) == 64 and d["input"]["image"]["path"] == str(image)
    assert d["config"]["core"]["working_width"] == 128 and d["config"]["monitor"] is None
    overlay = read_image(out_png)
    assert overlay.shape == (H, W, 3)


def test_land_options_reach_the_configuration(main, scene, tmp_path):
    labels, _ = scene
    out = tmp_path / "d.json"
    rc = main(["land", "--labels", str(labels), "--json", str(out), "--mode", "paper", "--height", "40",
               "--pitch", "50", "--camera", "phantom3pro", "--working-width", "128"])
    assert rc == 0
    d = json.loads(out.read_text())
    core = d["config"]["core"]
    assert core["mode"] == "paper"
    assert core["intrinsics"]["name"] == "phantom3pro"
    # the pose typed on the command line plans the frame and is recorded as such; the nominal pose stays the system's
    assert d["input"]["pose"] == {"height_m": 40.0, "pitch_deg": 50.0, "source": "command_line"}
    assert core["pose"] == {"height_m": 50.0, "pitch_deg": 45.0}
    jsonschema.validate(d, decision_schema())
    rc = main(["land", "--labels", str(labels), "--json", str(out), "--working-width", "128"])
    assert rc == 0 and json.loads(out.read_text())["input"]["pose"]["source"] == "nominal"  # none given


def test_positional_image_with_labels_is_the_image_to_draw_on(main, scene, tmp_path):
    labels, image = scene
    out = tmp_path / "d.json"
    assert main(["land", str(image), "--labels", str(labels), "--json", str(out), "--working-width", "128"]) == 0
    assert json.loads(out.read_text())["input"]["image"]["path"] == str(image)


def test_all_forbidden_labels_give_the_default_action(main, tmp_path, capsys):
    labels = tmp_path / "road.png"
    write_labels(labels, np.full((H, W), CLASS_IDS["road"], dtype=np.uint8), labels=UAVID)
    out = tmp_path / "d.json"
    assert main(["land", "--labels", str(labels), "--json", str(out), "--working-width", "128"]) == 0
    assert "DEFAULT action" in capsys.readouterr().out
    d = json.loads(out.read_text())
    assert d["action"] == "default" and d["reason"] == "no_candidate" and d["selected"] is None


# -- bad input: one line naming the file and the problem, exit 2, no traceback --------------------
def test_missing_labels_file(main, tmp_path, capsys):
    missing = tmp_path / "nope.png"
    assert main(["land", "--labels", str(missing)]) == 2
    one_line_error(capsys, str(missing), "no such file")


def test_labels_that_are_not_an_image(main, tmp_path, capsys):
    bogus = tmp_path / "notes.txt"
    bogus.write_text("these are not labels\n")
    assert main(["land", "--labels", str(bogus)]) == 2
    one_line_error(capsys, str(bogus), "not a readable image")


def test_truncated_png(main, scene, tmp_path, capsys):
    labels, _ = scene
    cut = tmp_path / "cut.png"
    data = labels.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    assert main(["land", "--labels", str(cut)]) == 2
    one_line_error(capsys, str(cut), "truncated")


def test_wrong_label_colours(main, tmp_path, capsys):
    rgb = np.zeros((H, W, 3), dtype=np.uint8)
    rgb[:10, :10] = (1, 2, 3)
    bad = tmp_path / "bad_colours.png"
    write_image(bad, rgb)
    assert main(["land", "--labels", str(bad)]) == 2
    one_line_error(capsys, str(bad), "RGB(1,2,3)", "100")


def test_image_and_labels_of_different_sizes(main, scene, tmp_path, capsys):
    labels, _ = scene
    small = tmp_path / "small.png"
    write_image(small, np.zeros((H // 2, W // 2, 3), dtype=np.uint8))
    assert main(["land", "--labels", str(labels), "--image", str(small)]) == 2
    one_line_error(capsys, str(labels), str(small), "differs")


def test_truncated_image(main, scene, tmp_path, capsys):
    labels, image = scene
    cut = tmp_path / "cut_image.png"
    data = image.read_bytes()
    cut.write_bytes(data[:-20])
    assert main(["land", "--labels", str(labels), "--image", str(cut), "--working-width", "128"]) == 2
    one_line_error(capsys, str(cut), "truncated")


def test_model_pipeline_without_weights_takes_default_action(main, scene, tmp_path, capsys, monkeypatch):
    import el.segmentation.weights as weights_module

    monkeypatch.setattr(weights_module, "DEFAULT_WEIGHTS", tmp_path / "no-weights.pt")
    _, image = scene
    out = tmp_path / "d.json"
    code = main(["land", str(image), "--working-width", "128", "--json", str(out)])
    assert code == 3
    d = json.loads(out.read_text())
    assert d["action"] == "default" and d["reason"].startswith("fault")
    jsonschema.validate(d, decision_schema())
    assert main(["land"]) == 2
    one_line_error(capsys, "--labels")


@pytest.mark.requirements("EL-R06")
def test_model_pipeline_with_weights(main, scene, tmp_path, capsys, monkeypatch):
    import torch

    from assurance.fitting.network.weights_io import save_weights
    from el.segmentation.architectures import build_model
    from el.segmentation.model import ArchConfig

    torch.manual_seed(0)
    weights = tmp_path / "tiny.pt"
    save_weights(build_model(ArchConfig(widths=(8, 8, 8), ms_channels=8, decoder_channels=8)), weights)
    _, image = scene
    out, ov = tmp_path / "d.json", tmp_path / "ov.png"
    log = tmp_path / "flight.jsonl"
    for _ in range(2):  # --log appends one record per decision
        code = main(["land", str(image), "--weights", str(weights), "--monitor", "lhd+ch:tau=0.25", "--json",
                     str(out), "--overlay", str(ov), "--working-width", "1024", "--log", str(log)])
        assert code == 0, capsys.readouterr().err
    d = json.loads(out.read_text())
    jsonschema.validate(d, decision_schema())
    records = [json.loads(line) for line in log.read_text().splitlines()]
    assert len(records) == 2 and records[0]["frame"]["sha256"] == d["input"]["sha256"]
    assert records[1]["action"] == d["action"]
    assert d["config"]["monitor"] == "lhd+ch:tau=0.25"
    assert read_image(ov).shape == (H, W, 3)
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png")
    assert main(["land", str(bad), "--weights", str(weights)]) == 2
    one_line_error(capsys, "bad.png")
    weights.write_bytes(weights.read_bytes()[:-8] + b"tampered")
    assert main(["land", str(image), "--weights", str(weights)]) == 2
    one_line_error(capsys, "tiny.pt")


@pytest.mark.parametrize("option,value,needle", [("--height", "0", "height_m"), ("--pitch", "120", "pitch_deg"),
                                                 ("--working-width", "4", "working_width")])
def test_bad_pose_or_option_values(main, scene, capsys, option, value, needle):
    labels, _ = scene
    assert main(["land", "--labels", str(labels), option, value]) == 2
    one_line_error(capsys, needle)


def test_unwritable_output(main, scene, tmp_path, capsys):
    labels, _ = scene
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["land", "--labels", str(labels), "--json", str(blocker / "d.json"), "--working-width", "128"]) == 2
    one_line_error(capsys, "cannot write")


# -- the overlay ----------------------------------------------------------------------------------------
def test_overlay_colours_candidates_by_status():
    verdicts = [MonitorVerdict("lhd", False, "unsafe pixels", 0.01), MonitorVerdict("lhd", True, "ok", 0.01), None]
    cands = [Candidate(k, 60.0 + 70 * k, 80.0, 20.0, 0.1 * k, 0.1 * k, 0.1 * k, v) for k, v in enumerate(verdicts)]
    decision = Decision(action="land", reason="accepted", selected=1, candidates=cands,
                        default_area=Disc(128.0, 124.0, 20.0), input={"width": W, "height": H})
    img = draw_decision(decision)
    assert img.dtype == np.uint8 and img.shape == (H, W, 3)

    def has_colour(x, y, colour, radius=3):
        patch = img[y - radius : y + radius + 1, x - radius : x + radius + 1].reshape(-1, 3).astype(int)
        return (np.abs(patch - np.array(colour)).sum(axis=1) < 60).any()

    assert has_colour(60 + 20, 80, STATUS_COLOURS["rejected"])  # right edge of disc 0
    assert has_colour(130 + 20, 80, STATUS_COLOURS["accepted"])
    assert has_colour(200 + 20, 80, STATUS_COLOURS["not examined"])
    # the unreachable top stripes are darkened
    assert img[5, W // 2].sum() < 96 * 3
    # the same from the JSON dict
    np.testing.assert_array_equal(draw_decision(decision.to_dict()), img)


def test_overlay_on_labels_and_on_an_image():
    ids = np.full((H, W), CLASS_IDS["low_vegetation"], dtype=np.uint8)
    decision = Decision(action="default", reason="no_candidate", selected=None, candidates=[],
                        default_area=Disc(128.0, 124.0, 20.0), input={"width": W, "height": H})
    on_labels = draw_decision(decision, labels=ids)
    on_image = draw_decision(decision, image=np.zeros((H, W, 3), np.uint8), labels=ids, labels_alpha=0.5)
    assert on_labels.shape == on_image.shape == (H, W, 3)
    assert not np.array_equal(on_labels, on_image)
    with pytest.raises(ValueError):
        draw_decision(decision, image=np.zeros((H, W), np.uint8))
    # bgr/rgb: the default area is drawn in blue (RGB), so its right edge is blue-dominant
    edge = on_labels[124, 128 + 20]
    assert edge[2] > edge[0]
    assert cv2 is not None


def test_land_builds_each_part_and_decodes_the_frame_once(main, scene, tmp_path, monkeypatch):
    """``uav-el land`` (model pipeline, the shipped system with its monitor and gate) loads the network, builds the
    monitor, reads the gate in the flight code and decodes the frame once each, also when it draws the overlay; a
    pose typed on the command line is recorded as such."""
    import collections

    import el.base.imageio
    import el.flight.pipeline
    import el.monitors.frame_gate
    from assurance.system.system import System

    calls: collections.Counter = collections.Counter()

    def count(owner, name, key):
        fn = getattr(owner, name)
        monkeypatch.setattr(owner, name, lambda *a, **k: calls.update([key]) or fn(*a, **k))

    count(System, "segmenter", "model")
    count(el.flight.pipeline, "build_monitor", "monitor")
    count(el.monitors.frame_gate, "load_frame_gate", "gate")  # GateFile.load reads through it
    count(el.base.imageio, "_decode_frame", "decode")
    _, image = scene
    out, ov = tmp_path / "d.json", tmp_path / "ov.png"
    assert main(["land", str(image), "--json", str(out), "--overlay", str(ov), "--height", "48"]) == 0
    assert calls == {"model": 1, "monitor": 1, "gate": 1, "decode": 1}, calls
    d = json.loads(out.read_text())
    assert d["input"]["frame_gate"] is not None and d["input"]["pose"]["source"] == "command_line"
    assert d["input"]["pose"]["height_m"] == 48.0 and read_image(ov).shape == (H, W, 3)
