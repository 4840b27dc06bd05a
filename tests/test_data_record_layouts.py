"""The report's data-management record on a data layout other than UAVid (``assurance.evidence.records``,
``assurance.evidence.disjoint``): a Semantic-Drone-layout folder holding the test, training and validation splits as
list files, the network's development data named by split in ``[model.provenance]``, a frame gate fitted on the
training split: each set's frames are counted through its layout, and the test split is compared frame by frame
(by image content) with every development set, passing when disjoint and failing when a test frame is in training.
Tiny fixtures written here, nothing downloaded."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from assurance import cli
from assurance.dataio.uavid import write_image
from el.classes.labels import UAVID, load_label_set

DRONE = load_label_set("semantic_drone")
TO_DRONE = {"road": "paved-area", "building": "roof", "static_car": "car", "moving_car": "car", "tree": "tree",
            "low_vegetation": "grass", "human": "person", "clutter": "gravel"}
SPLITS = {"test": ["000", "001"], "train": ["002", "003", "004"], "val": ["005", "006"]}


def _drone_folder(root: Path) -> None:
    """original_images/NNN.jpg, grey label_images_semantic/NNN.png (class id + 1) and one list file per split."""
    import cv2
    from helpers import scene_ids

    lut = np.array([DRONE.names.index(TO_DRONE[n]) for n in UAVID.names], np.uint8)
    for i, name in enumerate(n for names in SPLITS.values() for n in names):
        ids = scene_ids(256, 144, seed=i)
        write_image(root / "original_images" / f"{name}.jpg", UAVID.ids_to_colors(ids))
        (root / "label_images_semantic").mkdir(parents=True, exist_ok=True)
        assert cv2.imwrite(str(root / "label_images_semantic" / f"{name}.png"), lut[ids] + 1)
    for split, names in SPLITS.items():
        (root / f"{split}.txt").write_text("\n".join(names) + "\n")


def _table(split: str) -> str:
    return f'{{ path = "sdd", layout = "semantic-drone", split = "{split}.txt" }}'


@pytest.fixture(scope="module")
def drone_run(tmp_path_factory):
    """A system file over the folder's three splits (its training data named by split), a frame gate fitted on the
    training split, and a campaign on the test split with that gate."""
    tmp = tmp_path_factory.mktemp("drone")
    _drone_folder(tmp / "sdd")
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_DRONE.items())
    unreachable = [n for n in DRONE.names if n not in TO_DRONE.values()]
    text = (f'format = "uav-el-system/1"\n[labels]\npreset = "semantic_drone"\n'
            f'[model]\nclass_map = {{ {class_map} }}\nunreachable = {json.dumps(unreachable)}\n'
            f'[model.provenance]\ntrained_by = "Example Ltd."\ntraining_data = {_table("train")}\n'
            f'validation_data = {_table("val")}\n'
            '[odd]\nperturbations = { gaussian_noise = 3 }\n[monitor]\nspec = "lhd"\n'
            '[data]\nprovenance = "our garden, 2024"\nlicence = "CC-BY-4.0"\n'
            + "".join(f"{s} = {_table(s)}\n" for s in SPLITS))
    sys_file = tmp / "uav-el.toml"
    sys_file.write_text(text)
    gate, run = tmp / "gate.json", tmp / "run"
    assert cli.main(["fit-gate", "--system", str(sys_file), "--out", str(gate), "--no-progress"]) == 0
    assert cli.main(["campaign", "--system", str(sys_file), "--out", str(run), "--perturbations", "none",
                     "--monitors", "lhd", "--gate", str(gate), "--quiet"]) == 0
    return {"root": tmp, "system": sys_file, "gate": gate, "run": run}


def _record(case: dict) -> dict:
    from assurance.evidence.facts import report_facts
    from assurance.evidence.records import data_record
    from assurance.system import load_system

    system = load_system(case["system"])
    manifest = json.loads((case["run"] / "manifest.json").read_text())
    manifest = manifest.get("body", manifest)
    return data_record(manifest, report_facts(system, manifest), None, system)


def test_the_gate_records_where_its_data_are_and_which_split(drone_run):
    body = json.loads(drone_run["gate"].read_text())["body"]
    root = (drone_run["root"] / "sdd").resolve().as_posix()
    assert body["training"]["spec"] == {"path": root, "layout": "semantic-drone", "split": "train.txt"}
    assert body["validation"]["spec"]["split"] == "val.txt" and body["training"]["scenes"] == [0, 3]


def test_each_set_is_counted_in_its_layout_and_the_disjoint_splits_pass(drone_run):
    record = _record(drone_run)
    by_role = {d["role"]: d for d in record["datasets"]}
    assert by_role["verification (this campaign)"]["images"] == 2
    assert by_role["network training"]["images"] == 3 and by_role["network validation"]["images"] == 2
    assert by_role["network training"]["name"].endswith("sdd (split train.txt)")
    assert len(by_role["network training"]["sha256"]) == 64
    gate = by_role["frame gate fit"]  # located from its record, its provenance from [data] of that folder
    assert not gate["unread"] and gate["provenance"] == "our garden, 2024 (declared: [data] provenance)"
    assert gate["licence"] == "CC-BY-4.0 (declared in the system file)"
    shared = {c["check"]: c for c in record["disjoint"] if c["check"].startswith("no scene or image shared")}
    assert len(shared) == 4, record["disjoint"]  # training and validation, declared and the gate's
    assert {c["result"] for c in shared.values()} == {"pass"}, shared
    train = next(c for k, c in shared.items() if k.endswith("(split train.txt)"))
    assert "0 identical image file(s)" in train["detail"] and "3 development images" in train["detail"]


def test_a_test_frame_copied_into_training_fails_the_check(drone_run, tmp_path):
    case = dict(drone_run)
    copy = tmp_path / "copy"
    shutil.copytree(drone_run["root"], copy, ignore=shutil.ignore_patterns("run"))
    # the training split gets a frame whose bytes are a test frame's, under a new name
    shutil.copy(copy / "sdd" / "original_images" / "000.jpg", copy / "sdd" / "original_images" / "900.jpg")
    shutil.copy(copy / "sdd" / "label_images_semantic" / "000.png", copy / "sdd" / "label_images_semantic" / "900.png")
    (copy / "sdd" / "train.txt").write_text("002\n003\n004\n900\n")
    manifest = json.loads((drone_run["run"] / "manifest.json").read_text())
    body = manifest.get("body", manifest)
    body["data"]["path"] = str((copy / "sdd").resolve())
    body["data"]["spec"]["path"] = body["data"]["path"]
    body["config"].pop("gate", None)  # only the declared development data
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "manifest.json").write_text(json.dumps(body))
    case.update(system=copy / "uav-el.toml", run=tmp_path / "run")
    record = _record(case)
    (train,) = [c for c in record["disjoint"] if c["check"].endswith("(split train.txt)")]
    assert train["result"] == "fail" and "1 identical image file(s)" in train["detail"], train
    assert record["summary"].startswith("NOT disjoint")
    (val,) = [c for c in record["disjoint"] if c["check"].endswith("(split val.txt)")]
    assert val["result"] == "pass"


def test_a_card_with_a_path_relative_to_where_it_was_made_cannot_be_located(drone_run, tmp_path):
    from assurance.evidence.records import development_sets

    rows = development_sets(None, {"frame_gate.json": {"training": {"path": "data", "frames": 6, "sha256": "x"}}})
    assert rows[0]["unread"].startswith("data: cannot be located")
    from assurance.evidence.disjoint import disjointness

    (check,) = [c for c in disjointness([], "y", drone_run["root"] / "sdd", rows) if c["check"].endswith("data")]
    assert check["result"] == "not checked" and "cannot be located" in check["detail"]
