"""Per-frame poses ([camera], the per-frame pose worked example): the seqNN/poses.csv sidecar, scenes rendered at
per-frame heights and pitches, campaigns and the ground-truth pipeline planning each frame at its pose,
and the camera/pose options of ``uav-el land`` and ``uav-el synth``."""

import json
import shutil

import numpy as np
import pytest
from helpers import OracleSegmenter

from assurance import cli
from assurance.campaign import readouts
from assurance.campaign.gt_pipeline import decide_sample
from assurance.campaign.run import CampaignConfig, Execution, plan, run_campaign
from assurance.dataio.poses import FramePose, frame_pose, read_poses, write_poses
from assurance.dataio.uavid import iter_samples, read_labels, write_labels
from assurance.scenes import World
from assurance.scenes.generate import ViewPlan, generate_scene, write_dataset
from el.base.errors import DataError
from el.classes.labels import CLASS_IDS, UAVID
from el.geometry.camera import CameraGeometry, Intrinsics, Pose
from el.geometry.config import CoreConfig
from el.landing.core import probs_from_labels, run_core

SIZE = (192, 108)
CAMERA = Intrinsics.from_fov(70.0, name="wide70")
VIEW = ViewPlan(intrinsics=CAMERA, heights=(20.0, 60.0), pitches=(50.0, 90.0))


# -- the sidecar file ------------------------------------------------------------------------------
def test_a_sidecar_round_trips_with_and_without_roll(tmp_path):
    poses = {"000001": FramePose(Pose(height_m=21.5, pitch_deg=80.25), -1.5), "000000": Pose(height_m=100.0)}
    write_poses(tmp_path / "poses.csv", poses)
    text = (tmp_path / "poses.csv").read_text()
    assert text.splitlines()[0] == "frame,height_m,pitch_deg,roll_deg"
    back = read_poses(tmp_path / "poses.csv")
    assert list(back) == ["000000", "000001"]
    assert back["000001"] == FramePose(Pose(height_m=21.5, pitch_deg=80.25), -1.5)
    write_poses(tmp_path / "p2.csv", {"a": Pose()})
    assert (tmp_path / "p2.csv").read_text() == "frame,height_m,pitch_deg\na,50.0,45.0\n"


@pytest.mark.parametrize("text, where", [
    ("", "empty poses file"),
    ("frame,height,pitch_deg\n", ":1: header must be frame,height_m,pitch_deg"),
    ("frame,height_m,pitch_deg\n000000,50,45\n000001,fifty,45\n", ":3: column height_m: 'fifty' is not a number"),
    ("frame,height_m,pitch_deg\n000000,50,95\n", ":2: column pitch_deg: '95' must lie in [5, 90] degrees"),
    ("frame,height_m,pitch_deg\n000000,0.2,45\n", ":2: column height_m: '0.2' must lie in [1, 500] m"),
    ("frame,height_m,pitch_deg\n000000,nan,45\n", ":2: column height_m: 'nan' must lie in"),
    ("frame,height_m,pitch_deg,roll_deg\n000000,50,45,12\n", ":2: column roll_deg: '12' must lie in [-5, 5]"),
    ("frame,height_m,pitch_deg\n000000,50,45\n000000,60,45\n", ":3: column frame: '000000' appears twice"),
    ("frame,height_m,pitch_deg\n000000,50\n", ":2: 2 column(s), the header has 3"),
    ("frame,height_m,pitch_deg\n../x,50,45\n", ":2: column frame: '../x' is not an image stem"),
])
def test_sidecar_errors_name_file_line_column_and_value(tmp_path, text, where):
    path = tmp_path / "poses.csv"
    path.write_text(text)
    with pytest.raises(DataError) as info:
        read_poses(path)
    assert str(info.value).startswith(str(path)) and where in str(info.value)


def test_a_sidecar_naming_a_frame_without_an_image_is_refused(tmp_path):
    ids = np.full((36, 64), CLASS_IDS["low_vegetation"], np.uint8)
    for frame in ("000000", "000001"):
        write_labels(tmp_path / "seq00" / "Images" / f"{frame}.png", ids, labels=UAVID)
        write_labels(tmp_path / "seq00" / "Labels" / f"{frame}.png", ids, labels=UAVID)
    (tmp_path / "seq00" / "poses.csv").write_text("frame,height_m,pitch_deg\n000000,40,60\n000007,40,60\n")
    with pytest.raises(DataError, match=r"poses.csv: frame '000007' has no image"):
        list(iter_samples(tmp_path, poses=True))
    assert all(s.pose is None for s in iter_samples(tmp_path))  # not read unless asked for
    (tmp_path / "seq00" / "poses.csv").write_text("frame,height_m,pitch_deg\n000000,40,60\n")
    first, second = iter_samples(tmp_path, poses=True)
    assert first.pose == Pose(height_m=40.0, pitch_deg=60.0) and second.pose is None
    nominal = Pose()
    assert frame_pose(first, "nominal", nominal) == (nominal, 0.0, "nominal")
    assert frame_pose(first, "required", nominal)[2] == "frame"
    assert frame_pose(second, "sidecar", nominal) == (nominal, 0.0, "nominal")
    with pytest.raises(DataError, match=r"seq00/poses.csv: no pose for frame '000001' \(poses required"):
        frame_pose(second, "required", nominal)
    with pytest.raises(ValueError, match="poses must be one of nominal, sidecar, required"):
        CampaignConfig(perturbations=("none",), poses="always")


# -- scenes rendered at per-frame poses --------------------------------------------------------------
@pytest.fixture(scope="module")
def posed(tmp_path_factory):
    """3 tiny scenes rendered at per-frame heights and pitches with a 70-degree camera, their sidecar,
    and a copy whose images are the label colours (so the oracle segments them perfectly)."""
    root = tmp_path_factory.mktemp("posed")
    write_dataset(root / "scenes", 3, split="test", size=SIZE, progress=False, view=VIEW)
    oracle = root / "oracle"
    shutil.copytree(root / "scenes", oracle)
    for label in (oracle / "seq00" / "Labels").iterdir():
        shutil.copy(label, oracle / "seq00" / "Images" / label.name)
    return root


def test_scenes_are_rendered_at_their_sidecar_pose(posed):
    poses = read_poses(posed / "scenes" / "seq00" / "poses.csv")
    assert len(poses) == 3 and len({p.pose for p in poses.values()}) == 3
    for frame, fp in poses.items():
        assert 20.0 <= fp.pose.height_m <= 60.0 and 50.0 <= fp.pose.pitch_deg <= 90.0
        meta = json.loads((posed / "scenes" / "seq00" / "meta" / f"{frame}.json").read_text())
        assert meta["pose"] == {"height_m": fp.pose.height_m, "pitch_deg": fp.pose.pitch_deg}
        assert meta["intrinsics"] == CAMERA.to_dict()
        # the road pixels lie on the world's roads seen with that pose, not with the nominal one
        ids = read_labels(posed / "scenes" / "seq00" / "Labels" / f"{frame}.png", labels=UAVID)
        world = World.from_meta(meta)
        rows, cols = np.nonzero(ids == CLASS_IDS["road"])
        share = {}
        for name, pose in (("own", fp.pose), ("nominal", Pose())):
            g = CameraGeometry(width=SIZE[0], height=SIZE[1], intrinsics=CAMERA, pose=pose)
            x, y = g.pixel_to_ground(cols, rows)
            share[name] = float(np.mean(world.clearance_m(x, y, classes=("road",)) == 0))
        assert share["own"] > 0.9 and share["own"] > share["nominal"] + 0.2, share


def test_scene_poses_are_drawn_from_the_seed(posed):
    again = generate_scene(2_000_001, size=SIZE, split="test", pose=VIEW.pose_for(2_000_001), intrinsics=CAMERA)
    assert again.meta["pose"] == json.loads((posed / "scenes" / "seq00" / "meta" / "000001.json").read_text())["pose"]
    assert VIEW.pose_for(5) == VIEW.pose_for(5) != VIEW.pose_for(6)


def test_a_campaign_requiring_poses_plans_each_frame_at_its_own(posed, tmp_path):
    data = tmp_path / "data"
    shutil.copytree(posed / "oracle", data)
    sidecar = read_poses(data / "seq00" / "poses.csv")
    core = CoreConfig(n_star=6, working_width=96, intrinsics=CAMERA)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), core=core, poses="required")
    assert config.to_dict()["poses"] == "required"
    assert "poses" not in CampaignConfig(perturbations=("none",)).to_dict()  # nominal records as before
    summary = run_campaign(data, tmp_path / "run", config, segmenter=OracleSegmenter(96),
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    images = readouts.load_table(tmp_path / "run", "images").set_index("frame")
    for frame, fp in sidecar.items():
        assert images.loc[frame, "height_m"] == fp.pose.height_m
        assert images.loc[frame, "pitch_deg"] == fp.pose.pitch_deg
        assert images.loc[frame, "pose_source"] == "frame"
    # the discs are the frame's: the same frame planned at the nominal pose gets other radii
    nominal = CampaignConfig(perturbations=("none",), monitors=("lhd",), core=core)
    run_campaign(data, tmp_path / "nominal", nominal, segmenter=OracleSegmenter(96),
                 execution=Execution(progress=False))
    nom = readouts.load_table(tmp_path / "nominal", "images").set_index("frame")
    assert (nom["pose_source"] == "nominal").all() and (nom["height_m"] == 50.0).all()
    assert not np.allclose(nom["default_r"].to_numpy(), images.loc[nom.index, "default_r"].to_numpy())

    # a frame missing from the sidecar: a recorded fault of its task under "required", nominal under "sidecar"
    lines = (data / "seq00" / "poses.csv").read_text().splitlines()
    (data / "seq00" / "poses.csv").write_text("\n".join(lines[:2] + lines[3:]) + "\n")  # drop frame 000001
    summary = run_campaign(data, tmp_path / "missing", config, segmenter=OracleSegmenter(96),
                           execution=Execution(progress=False))
    assert len(summary["faults"]) == 1 and "no pose for frame '000001'" in summary["faults"][0]
    faulted = readouts.load_table(tmp_path / "missing", "images").set_index("frame")
    assert faulted.loc["000001", "fault"].startswith("DataError")
    loose = CampaignConfig(perturbations=("none",), monitors=("lhd",), core=core, poses="sidecar")
    run_campaign(data, tmp_path / "loose", loose, segmenter=OracleSegmenter(96), execution=Execution(progress=False))
    got = readouts.load_table(tmp_path / "loose", "images").set_index("frame")
    assert got.loc["000001", "pose_source"] == "nominal" and got.loc["000000", "pose_source"] == "frame"


def test_without_a_sidecar_a_synthetic_scene_plans_at_its_rendered_pose(posed, tmp_path):
    data = tmp_path / "data"
    shutil.copytree(posed / "oracle", data)
    (data / "seq00" / "poses.csv").unlink()
    meta = json.loads((data / "seq00" / "meta" / "000002.json").read_text())["pose"]
    config = CampaignConfig(perturbations=("none",), core=CoreConfig(n_star=6, working_width=96, intrinsics=CAMERA),
                            poses="required")
    sample = plan(data, config)[2].sample
    assert frame_pose(sample, "required", Pose())[0] == Pose(**meta)
    decision = decide_sample(sample, config=config.core, poses="required", labels=UAVID)
    assert decision.input["pose"] == {**meta, "source": "frame"}
    (data / "seq00" / "meta" / "000002.json").unlink()
    sample = plan(data, config)[2].sample
    faulted = decide_sample(sample, config=config.core, poses="required", labels=UAVID)
    assert faulted.action == "default" and faulted.reason.startswith("fault: pose: DataError")


# -- the command line ---------------------------------------------------------------------------------
@pytest.fixture
def main(monkeypatch):
    monkeypatch.setattr(cli, "COMMANDS", {"land": "land", "synth": "synth"})
    return cli.main


def test_land_with_a_custom_camera(main, tmp_path, capsys):
    ids = np.full((108, 192), CLASS_IDS["low_vegetation"], np.uint8)
    ids[:, 90:96] = CLASS_IDS["road"]
    write_labels(tmp_path / "l.png", ids, labels=UAVID)
    out = tmp_path / "d.json"
    assert main(["land", "--labels", str(tmp_path / "l.png"), "--json", str(out), "--working-width", "96",
                 "--sensor-width", "6.3", "--hfov", "70", "--height", "30", "--pitch", "80", "--roll", "2"]) == 0
    d = json.loads(out.read_text())
    assert d["config"]["core"]["intrinsics"]["sensor_width_mm"] == 6.3
    assert d["input"]["pose"] == {"height_m": 30.0, "pitch_deg": 80.0, "source": "command_line", "roll_deg": 2.0}
    assert main(["land", "--labels", str(tmp_path / "l.png"), "--json", str(out), "--working-width", "96",
                 "--camera", "phantom4", "--focal", "4.4"]) == 0
    assert json.loads(out.read_text())["config"]["core"]["intrinsics"]["focal_mm"] == 4.4
    capsys.readouterr()
    for bad, says in ((["--hfov", "150"], "hfov_deg must lie in [5, 120] deg, got 150.0"),
                      (["--sensor-width", "6.3"], "needs focal_mm or hfov_deg"),
                      (["--focal", "0.1", "--sensor-width", "6"], "focal_mm must lie in [0.5, 2000] mm"),
                      (["--roll", "8"], "roll_deg must lie in [-5, 5] degrees"),
                      # a reachable row within 3 degrees of the horizon once a 5 degree roll tilts the edges
                      (["--hfov", "110", "--height", "5", "--pitch", "10", "--roll", "5"], "allowed: pitch_deg >= ")):
        assert main(["land", "--labels", str(tmp_path / "l.png"), *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and says in err, err
    # a wide lens at a low pitch is not refused: its far rows (beyond the reach) are unreachable, the near ones plan
    assert main(["land", "--labels", str(tmp_path / "l.png"), "--json", str(out), "--working-width", "96",
                 "--hfov", "110", "--pitch", "20"]) == 0
    d = json.loads(out.read_text())
    assert d["input"]["pose"] == {"height_m": 50.0, "pitch_deg": 20.0, "source": "command_line"}
    assert not d["reason"].startswith("fault")
    config = CoreConfig(working_width=96, intrinsics=Intrinsics.from_fov(110.0), pose=Pose(pitch_deg=20.0))
    result = run_core(probs_from_labels(ids, (96, 54), labels=UAVID), (192, 108), config, labels=UAVID)
    assert 0 < result.first_reachable_row < 108 and result.candidates
    assert all(c.y >= result.first_reachable_row for c in result.candidates)


def test_synth_options_and_their_errors(main, tmp_path, capsys):
    assert main(["synth", "--out", str(tmp_path / "s"), "--scenes", "1", "--size", "96x54", "--no-progress",
                 "--hfov", "70", "--heights", "30:40", "--pitches", "60:90", "--split", "test"]) == 0
    poses = read_poses(tmp_path / "s" / "seq00" / "poses.csv")
    assert 30 <= poses["000000"].pose.height_m <= 40
    capsys.readouterr()
    for bad, says in ((["--heights", "40:20"], "--heights must look like LOW:HIGH"),
                      (["--pitches", "1:90"], "pitches must be a range LOW:HIGH with 5 <= LOW"),
                      (["--pitch", "10"], "sees the horizon (top edge -12.9 deg below it); the generator models "
                                          "the ground only: raise the pitch"),
                      (["--hfov", "300"], "hfov_deg must lie in")):
        assert main(["synth", "--out", str(tmp_path / "x"), "--scenes", "1", "--size", "96x54", *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and says in err, err
    assert not (tmp_path / "x").exists()
