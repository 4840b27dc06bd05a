"""Data as users hold it (``assurance.dataio.layouts``): the UAVid, Semantic Drone, AeroScapes and flat-pairs
layouts and user patterns, read into the same samples; grey id maps and colour maps decoded through the system's
label set; a poses CSV keyed by image stem; ``[data]`` tables in a system file; ``uav-el preview`` on each layout and
a campaign on a Semantic-Drone-layout split declared in a system file. Tiny fixtures written here, nothing
downloaded."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from assurance import cli
from assurance.dataio.layouts import (
    DataSpec,
    data_source,
    ids_from_values,
    iter_samples,
    read_sample_labels,
    resolve,
    write_label_file,
)
from assurance.dataio.uavid import write_image, write_sample
from el.base.errors import DataError
from el.classes.labels import UAVID, load_label_set

W, H = 32, 24
DRONE = load_label_set("semantic_drone")  # 23 classes, unlabeled = ignore id 255


def frame(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)


def grey(path: Path, values: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), np.asarray(values, np.uint8))


def ids_map(seed: int, n: int) -> np.ndarray:
    """Class ids 0..n-1 in vertical bands (a different band order per seed)."""
    return ((np.arange(W)[None, :] // 4 + seed) % n * np.ones((H, 1), int)).astype(np.uint8)


def semantic_drone(root: Path, frames=("000", "001", "002")) -> Path:
    """original_images/NNN.jpg and label_images_semantic/NNN.png: 0 unlabeled, class id + 1 elsewhere."""
    for i, name in enumerate(frames):
        write_image(root / "original_images" / f"{name}.jpg", frame(i))
        values = ids_map(i, len(DRONE.names)) + 1
        values[0, 0] = 0  # one unlabelled pixel
        grey(root / "label_images_semantic" / f"{name}.png", values)
    return root


def aeroscapes(root: Path) -> Path:
    """JPEGImages/*.jpg, SegmentationClass/*.png grey ids 0..7 (UAVid's 8 classes), ImageSets/{trn,val}.txt."""
    names = ["000001_001", "000001_002", "000002_001", "000002_002"]
    for i, name in enumerate(names):
        write_image(root / "JPEGImages" / f"{name}.jpg", frame(10 + i))
        grey(root / "SegmentationClass" / f"{name}.png", ids_map(i, 8))
    (root / "ImageSets").mkdir()
    (root / "ImageSets" / "trn.txt").write_text("000001_001\n000002_001\n")
    (root / "ImageSets" / "val.txt").write_text("000001_002\n000002_002\n")
    return root


def pairs(root: Path, *, folder: bool = False) -> Path:
    """NAME.png with NAME_label.png (or labels/NAME.png) in UAVid colours."""
    for i, name in enumerate(("b", "a")):
        write_image(root / f"{name}.png", frame(20 + i))
        label = root / "labels" / f"{name}.png" if folder else root / f"{name}_label.png"
        write_image(label, UAVID.ids_to_colors(ids_map(i, 8)))
    return root


# -- finding the pairs ------------------------------------------------------------------------------------------------
def test_a_semantic_drone_folder_is_detected_and_its_grey_maps_read_with_the_offset(tmp_path):
    root = semantic_drone(tmp_path / "sdd")
    samples = list(iter_samples(root))
    assert [s.key for s in samples] == ["original_images/000", "original_images/001", "original_images/002"]
    assert [s.label_path.name for s in samples] == ["000.png", "001.png", "002.png"]
    assert all(s.image_path.suffix == ".jpg" and s.label_encoding == "ids" and s.id_offset == 1 for s in samples)
    ids = read_sample_labels(samples[1], DRONE)
    want = ids_map(1, len(DRONE.names))
    want[0, 0] = 255  # value 0 is the set's ignore (unlabeled)
    assert ids.dtype == np.uint8 and np.array_equal(ids, want)
    assert not samples[0].meta_path().exists()  # no scene metadata: "not declared"
    copy = tmp_path / "copy.png"  # written back in the same encoding (uav-el recolour keeps a data set's own)
    write_label_file(copy, ids, DRONE, encoding="ids", id_offset=1)
    assert np.array_equal(cv2.imread(str(copy), cv2.IMREAD_UNCHANGED), cv2.imread(str(samples[1].label_path),
                                                                                 cv2.IMREAD_UNCHANGED))


def test_aeroscapes_is_detected_and_a_list_file_picks_its_split(tmp_path):
    root = aeroscapes(tmp_path / "aero")
    assert resolve(root).layout == "aeroscapes"
    assert [s.frame for s in iter_samples(root)] == ["000001_001", "000001_002", "000002_001", "000002_002"]
    val = list(iter_samples(DataSpec(root, split="ImageSets/val.txt")))
    assert [s.key for s in val] == ["JPEGImages/000001_002", "JPEGImages/000002_002"]
    assert np.array_equal(read_sample_labels(val[1], UAVID), ids_map(3, 8))


def test_pairs_beside_or_in_a_labels_folder_read_as_colour_maps(tmp_path):
    for folder in (False, True):
        root = pairs(tmp_path / f"pairs-{folder}", folder=folder)
        samples = list(iter_samples(DataSpec(root, layout="pairs")))
        assert [s.key for s in samples] == ["pairs/a", "pairs/b"]  # label files are not images
        assert samples[0].label_path.name == ("a.png" if folder else "a_label.png")
        assert np.array_equal(read_sample_labels(samples[0], UAVID), ids_map(1, 8))


def test_patterns_with_a_template_and_nested_folders(tmp_path):
    for seq in ("north", "south"):
        for i in range(2):
            write_image(tmp_path / "flights" / seq / "rgb" / f"f{i}.jpg", frame(i))
            grey(tmp_path / "flights" / seq / "gt" / f"f{i}_gt.png", ids_map(i, 8))
    spec = DataSpec(tmp_path, images="flights/*/rgb/*.jpg", labels="{dir}/../gt/{stem}_gt.png",
                    label_encoding="ids")
    samples = list(iter_samples(spec))
    assert [s.key for s in samples] == ["flights/north/rgb/f0", "flights/north/rgb/f1", "flights/south/rgb/f0",
                                        "flights/south/rgb/f1"]  # the same stem in two folders: distinct keys
    assert samples[3].label_path == tmp_path / "flights" / "south" / "gt" / "f1_gt.png"
    assert np.array_equal(read_sample_labels(samples[3], UAVID), ids_map(1, 8))


def test_the_uavid_layout_reads_as_before(tmp_path):
    write_sample(tmp_path, "seq01", "000001", frame(0), ids_map(0, 8), labels=UAVID)
    write_sample(tmp_path, "seq00", "000007", frame(1), ids_map(1, 8), labels=UAVID)
    samples = list(iter_samples(tmp_path))
    assert [s.key for s in samples] == ["seq00/000007", "seq01/000001"] and samples[0].label_encoding == "rgb"
    assert samples[0].meta_path() == tmp_path / "seq00" / "meta" / "000007.json"
    assert np.array_equal(read_sample_labels(samples[1], UAVID), ids_map(0, 8))


# -- one-line errors naming the file ----------------------------------------------------------------------------------
def test_a_value_that_is_no_class_is_named_with_its_file_and_pixel(tmp_path):
    root = aeroscapes(tmp_path / "aero")
    bad = ids_map(0, 8)
    bad[5, 7] = 9
    grey(root / "SegmentationClass" / "000001_001.png", bad)
    with pytest.raises(DataError) as err:
        read_sample_labels(next(iter_samples(root)), UAVID)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(root / "SegmentationClass" / "000001_001.png"))
    assert "value 9 at (x=7, y=5)" in msg and "'uavid'" in msg
    # a set without an ignore colour: below the offset is an error too; the ignore id reads as unlabelled
    with pytest.raises(DataError, match="value 0"):
        ids_from_values(np.array([[0, 1]]), UAVID, id_offset=1, source="x.png")
    assert ids_from_values(np.array([[255, 1, 0]]), DRONE, id_offset=1).tolist() == [[255, 0, 255]]


def test_a_missing_label_an_unknown_layout_and_a_grey_map_read_as_colours(tmp_path):
    root = semantic_drone(tmp_path / "sdd")
    (root / "label_images_semantic" / "001.png").unlink()
    with pytest.raises(DataError, match=r"001\.jpg: image has no label map .*label_images_semantic/001\.png"):
        list(iter_samples(root))
    assert [s.label_path is None for s in iter_samples(root, require_labels=False)] == [False, True, False]
    with pytest.raises(DataError) as err:
        list(iter_samples(tmp_path / "sdd" / "original_images"))
    assert str(err.value).startswith(str(tmp_path / "sdd" / "original_images") + ": no known data layout")
    assert "uavid, semantic-drone, aeroscapes, pairs" in str(err.value)
    with pytest.raises(DataError, match=r"000\.png: .*single-channel.*label_encoding = \"ids\""):
        read_sample_labels(next(iter_samples(DataSpec(root, label_encoding="rgb"), require_labels=False)), DRONE)
    (root / "split.txt").write_text("000\nnope\n")
    with pytest.raises(DataError, match=r"split\.txt:2: 'nope' names no image"):
        list(iter_samples(DataSpec(root, split="split.txt"), require_labels=False))


@pytest.mark.parametrize("table, problem", [
    ({"layout": "kitti"}, "layout: 'kitti' is not a known layout"),
    ({"layout": "pairs", "images": "*.jpg"}, "layout: give a layout or images/labels patterns, not both"),
    ({"images": "*.jpg", "labels": "labels/{frame}.png"}, "unknown placeholder {frame}"),
    ({"images": "*.jpg", "labels": "labels/x.png"}, "the same file for every image"),
    ({"images": "../other/*.jpg"}, "must be relative to path and stay under it"),
    ({"label_encoding": "grey"}, "label_encoding: must be one of rgb, ids"),
])
def test_a_bad_table_is_refused_naming_the_key(tmp_path, table, problem):
    with pytest.raises(ValueError, match=problem.replace("{", r"\{").replace("(", r"\(")):
        DataSpec.from_dict({"path": str(tmp_path), **table})


# -- poses ------------------------------------------------------------------------------------------------------------
def test_a_poses_csv_gives_each_frame_its_pose(tmp_path):
    root = semantic_drone(tmp_path / "sdd")
    (root / "flight").mkdir()
    (root / "flight" / "log.csv").write_text("frame,height_m,pitch_deg,roll_deg\n002,25.0,88.0,1.5\n000,30,80\n"
                                             .replace("000,30,80", "000,30,80,0"))
    samples = list(iter_samples(DataSpec(root, poses="flight/log.csv"), poses=True))
    got = {s.frame: (s.pose and (s.pose.height_m, s.pose.pitch_deg), s.roll_deg) for s in samples}
    assert got == {"000": ((30.0, 80.0), 0.0), "001": (None, 0.0), "002": ((25.0, 88.0), 1.5)}
    assert all(s.poses_path == root / "flight" / "log.csv" for s in samples)
    assert all(s.pose is None for s in iter_samples(DataSpec(root, poses="flight/log.csv")))  # not asked: not read
    (root / "poses.csv").write_text("frame,height_m,pitch_deg\n001,40,70\n")  # a flat layout's default CSV
    assert [s.pose is not None for s in iter_samples(root, poses=True)] == [False, True, False]
    (root / "poses.csv").write_text("frame,height_m,pitch_deg\n009,40,70\n")
    with pytest.raises(DataError, match=r"poses\.csv: frame '009' has no image"):
        list(iter_samples(root, poses=True))


def test_a_stem_shared_by_two_folders_is_refused_by_a_poses_csv(tmp_path):
    for seq in ("a", "b"):
        write_image(tmp_path / seq / "x.jpg", frame(0))
    (tmp_path / "poses.csv").write_text("frame,height_m,pitch_deg\nx,40,70\n")
    with pytest.raises(DataError, match=r"frame 'x' names 2 images \(a/x, b/x\)"):
        list(iter_samples(DataSpec(tmp_path, images="*/*.jpg", poses="poses.csv"), require_labels=False, poses=True))


# -- the system file and the commands ---------------------------------------------------------------------------------
def system(folder: Path, data: str, labels: str = "semantic_drone") -> Path:
    path = folder / "uav-el.toml"
    path.write_text(f'format = "uav-el-system/1"\n[labels]\npreset = "{labels}"\n{data}')
    return path


def test_data_tables_resolve_against_the_system_file(tmp_path):
    from assurance.system import SystemFileError, load_system
    from assurance.system.build import data_root

    semantic_drone(tmp_path / "data" / "sdd")
    sub = tmp_path / "conf"
    sub.mkdir()
    text = ('[data]\ntrain = "../data/sdd"\nval = { path = "../data/sdd", split = "val.txt" }\n'
            '[data.test]\npath = "../data/sdd"\nlayout = "semantic-drone"\nposes = "poses.csv"\n')
    loaded = load_system(system(sub, text))
    assert data_root(loaded, "train") == tmp_path / "data/sdd"  # normalised: one spelling of one folder
    test = data_root(loaded, "test")
    assert isinstance(test, DataSpec) and test.path == tmp_path / "data/sdd" and test.poses == "poses.csv"
    assert data_root(loaded, "test", "elsewhere") == Path("elsewhere")  # an option wins
    for bad, problem in (('[data.test]\npath = "../data/sdd"\nfolder = "x"\n', "unknown key data.test.folder"),
                         ('[data.test]\npath = "../data/sdd"\nlayout = "kitti"\n', "data.test.layout"),
                         ('[data.test]\npath = "../nope"\n', "data.test: .*nope: no such folder"),
                         ('[data.test]\nlayout = "pairs"\n', "data.test: missing key")):
        with pytest.raises(SystemFileError, match=problem) as err:
            data_root(load_system(system(sub, bad)), "test")
        assert "\n" not in str(err.value)


def test_preview_shows_every_layout(tmp_path, capsys):
    sdd = semantic_drone(tmp_path / "sdd")
    aero = aeroscapes(tmp_path / "aero")
    flat = pairs(tmp_path / "flat")
    uavid_system = system(tmp_path, "", labels="uavid")
    write_sample(tmp_path / "uavid", "seq00", "000000", frame(0), ids_map(0, 8), labels=UAVID)
    cases = [(["--data", str(sdd)], system(tmp_path / "sdd", "")),
             (["--data", str(aero), "--count", "4"], uavid_system),
             (["--data", str(tmp_path / "uavid")], uavid_system)]
    (tmp_path / "p").mkdir()
    cases.append(([], system(tmp_path / "p", f'[data.test]\npath = "{flat}"\nlayout = "pairs"\n', labels="uavid")))
    for i, (args, sys_file) in enumerate(cases):
        out = tmp_path / f"preview{i}.png"
        assert cli.main(["preview", *args, "--system", str(sys_file), "--out", str(out), "--width", "64"]) == 0
        assert out.stat().st_size > 0
    assert "preview of 4 sample(s)" in capsys.readouterr().out
    assert cli.main(["preview", "--system", str(uavid_system), "--out", str(tmp_path / "x.png")]) == 2
    assert "data.test: not set" in capsys.readouterr().err


# -- a campaign on a Semantic-Drone-layout split declared in the system file ------------------------------------------
TO_DRONE = {"road": "paved-area", "building": "roof", "static_car": "car", "moving_car": "car", "tree": "tree",
            "low_vegetation": "grass", "human": "person", "clutter": "gravel"}


def test_a_campaign_reads_a_semantic_drone_split_from_the_system_file(tmp_path):
    """The shipped network mapped onto the Semantic Drone classes, its test split a [data.test] table: every frame is
    evaluated without a fault, the manifest records the spec, and the run's frames are found again from it."""
    from helpers import scene_ids

    from assurance.campaign import readouts
    from assurance.campaign.run import manifest, plan

    lut = np.array([DRONE.names.index(TO_DRONE[n]) for n in UAVID.names], np.uint8)
    root = tmp_path / "sdd"
    for i in range(3):
        ids = scene_ids(256, 144, seed=i)  # smaller: candidate patches too small to judge
        write_image(root / "original_images" / f"{i:03d}.jpg", UAVID.ids_to_colors(ids))
        grey(root / "label_images_semantic" / f"{i:03d}.png", lut[ids] + 1)
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_DRONE.items())
    unreachable = [n for n in DRONE.names if n not in TO_DRONE.values()]
    sys_file = system(tmp_path, f'[model]\nclass_map = {{ {class_map} }}\nunreachable = {json.dumps(unreachable)}\n'
                                '[monitor]\nspec = "lhd"\n[data.test]\npath = "sdd"\nlayout = "semantic-drone"\n')
    run = tmp_path / "run"
    assert cli.main(["campaign", "--system", str(sys_file), "--out", str(run), "--perturbations", "none",
                     "--monitors", "lhd", "--quiet"]) == 0
    images = readouts.load_table(run, "images")
    assert sorted(set(images["key"])) == ["original_images/000", "original_images/001", "original_images/002"]
    assert (images["fault"].fillna("") == "").all(), images["fault"].tolist()
    man = json.loads((run / "manifest.json").read_text())
    assert man["data"]["spec"] == {"path": str(root.resolve()), "layout": "semantic-drone"}
    again = data_source(man["data"])
    assert isinstance(again, DataSpec)
    from assurance.campaign.task import CampaignConfig

    config = CampaignConfig(perturbations=("none",), monitors=("lhd",))
    assert manifest(again, config, plan(again, config))["data"]["sha256"] == man["data"]["sha256"]
    from assurance.evidence.gallery import Scenes

    scenes = Scenes(again, man["config"]["seed"])  # the report's pictures: the run's frames, found from its spec
    assert not scenes.error and scenes.image("original_images/001", "none", 3).shape == (144, 256, 3)


def test_camera_files_as_they_come_upper_case_suffixes_and_one_stem_twice(tmp_path):
    """A pattern's *.jpg finds IMG_1.JPG too (it was skipped without a word); in the UAVid layout two images of one
    frame (000000.png beside 000000.jpg) are refused naming both (one was dropped by directory order)."""
    img = np.zeros((8, 8, 3), np.uint8)
    (tmp_path / "flat" / "images").mkdir(parents=True)
    for name in ("IMG_0.jpg", "IMG_1.JPG", "IMG_2.Jpg"):
        write_image(tmp_path / "flat" / "images" / name, img)
    found = list(iter_samples(DataSpec(tmp_path / "flat", images="images/*.jpg"), require_labels=False))
    assert [s.image_path.name for s in found] == ["IMG_0.jpg", "IMG_1.JPG", "IMG_2.Jpg"]
    write_sample(tmp_path / "uavid", "seq00", "000000", img, np.zeros((8, 8), np.uint8), labels=UAVID)
    write_image(tmp_path / "uavid" / "seq00" / "Images" / "000000.jpg", img)
    with pytest.raises(DataError, match=r"000000\.png: a second image of frame seq00/000000 \(the first: 000000\.jpg"):
        list(iter_samples(tmp_path / "uavid"))


def test_land_reads_a_label_file_of_class_ids_as_the_system_file_declares(tmp_path, capsys):
    """``land --labels`` read colours only, and its hint asked for the label_encoding the system file already set."""
    ids = np.zeros((360, 640), np.uint8)
    ids[:, 320:] = UAVID.ids["road"]
    (tmp_path / "data" / "masks").mkdir(parents=True)
    label = tmp_path / "data" / "masks" / "f0.png"
    cv2.imwrite(str(label), ids)
    write_image(tmp_path / "data" / "f0.jpg", np.zeros((360, 640, 3), np.uint8))
    system = tmp_path / "uav-el.toml"
    system.write_text('format = "uav-el-system/1"\n[data.test]\npath = "data"\nimages = "*.jpg"\n'
                      'labels = "masks/{stem}.png"\nlabel_encoding = "ids"\n')
    out = tmp_path / "d.json"
    assert cli.main(["land", "--labels", str(label), "--system", str(system), "--json", str(out)]) == 0
    assert not json.loads(out.read_text())["reason"].startswith("fault")
    assert cli.main(["land", "--labels", str(label), "--system", str(system), "--label-encoding", "rgb"]) == 2
    assert "single-channel" in capsys.readouterr().err
