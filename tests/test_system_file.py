"""The system file (uav-el.toml): validated on load, every error one line naming key, value and what is allowed;
its settings reach the commands; without one, the embedded default is today's shipped system."""

import json
import textwrap
from dataclasses import replace

import numpy as np
import pytest

from assurance import cli
from assurance.dataio.uavid import write_image, write_labels
from assurance.system import SystemFileError, default_system, find_system, load_system, schema
from assurance.system import build as system_build
from el.classes.labels import CLASS_IDS, UAVID
from el.geometry.camera import PHANTOM3_PRO, SafetyParams, geometry_problem
from el.geometry.config import CoreConfig

W, H = 256, 144


def write(tmp_path, text, name="uav-el.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text), encoding="utf-8")
    return p


@pytest.fixture
def scene(tmp_path):
    ids = np.full((H, W), CLASS_IDS["low_vegetation"], dtype=np.uint8)
    ids[70:74, :] = CLASS_IDS["road"]
    ids[90:120, 20:60] = CLASS_IDS["building"]
    labels, image = tmp_path / "labels.png", tmp_path / "image.png"
    write_labels(labels, ids, labels=UAVID)
    write_image(image, np.full((H, W, 3), 120, dtype=np.uint8))
    return labels, image


def test_the_embedded_default_is_the_shipped_system():
    system = default_system()
    assert system.default and system.path is None and len(system.sha256) == 64
    assert system_build.core_config(system) == CoreConfig()
    assert system_build.label_set(system) is UAVID
    assert system_build.model_kind(system) == "builtin"
    assert system_build.targets(system) == {}  # the default sets no requirement target: the registry's hold


def test_find_system_prefers_the_option_then_the_working_directory(tmp_path):
    assert find_system(None, cwd=tmp_path).default
    write(tmp_path, '[system]\nname = "here"\n')
    assert find_system(None, cwd=tmp_path).name == "here"
    other = write(tmp_path, '[system]\nname = "given"\n', name="other.toml")
    assert find_system(other, cwd=tmp_path).name == "given"


def test_settings_merge_over_the_default_and_paths_are_relative_to_the_file(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "waivers.yaml").write_text("waivers: []\n")
    system = load_system(write(tmp_path / "sub", """
        [camera]
        preset = "phantom3pro"
        height_m = 80
        [safety]
        radius_m = 3.5
        [waivers]
        file = "waivers.yaml"
        [targets]
        confidence = 0.99
    """))
    core = system_build.core_config(system)
    assert core.intrinsics == PHANTOM3_PRO
    assert core.pose.height_m == 80 and core.pose.pitch_deg == 45  # pitch from the default
    assert core.safety == SafetyParams(radius_m=3.5, beta=1.7)
    assert system_build.waivers(system) == str(tmp_path / "sub" / "waivers.yaml")
    assert system_build.targets(system) == {"confidence": 0.99, "radius_m": 3.5}
    assert ("camera.height_m", "80") in system.values()


def test_field_of_view_gives_the_focal_length(tmp_path):
    system = load_system(write(tmp_path, "[camera]\nsensor_width_mm = 10.0\nhfov_deg = 90.0\n"))
    intr = system_build.intrinsics(system)
    assert intr.sensor_width_mm == 10.0 and intr.focal_mm == pytest.approx(5.0)


@pytest.mark.parametrize("text, needles", [
    ("[camera]\nheigth_m = 50\n", ("unknown key camera.heigth_m", "height_m")),
    ("[cameras]\nheight_m = 50\n", ("unknown key cameras", "camera")),
    ('[camera]\nheight_m = "fifty"\n', ("camera.height_m", '"fifty"', "a number")),
    ("[camera]\nheight_m = 700\n", ("camera.height_m", "700", "<= 500")),
    ('[camera]\nposes = "maybe"\n', ("camera.poses", '"maybe"', "nominal")),
    ("[safety]\nbeta = 0.5\n", ("safety.beta", "0.5", ">= 1")),
    ("[targets]\nconfidence = 1.5\n", ("targets.confidence", "1.5", "< 1")),
    ('[targets]\nrequired_perturbations = ["rain"]\n', ("targets.required_perturbations", "rain", "fog")),
    ('[model]\nsha256 = "abc"\n', ("model.sha256", "64 lowercase hex")),
    ('[camera]\npreset = "gopro"\n', ("camera.preset", "gopro", "phantom4")),
    ("[camera]\nfocal_mm = 8.8\nhfov_deg = 70\n", ("camera", "focal_mm or hfov_deg")),
    ('[monitor]\nspec = "nonsense:x=1"\n', ("monitor.spec",)),
    ('[model]\nclass_map = {road = "asphalt"}\n', ("model.class_map", "asphalt")),
    ('[model]\npath = "missing.onnx"\n', ("model.path", "no such file")),
    ("camera = 3\n", ("camera = 3", "a table")),
    ("[camera\n", ("not valid TOML",)),
])
def test_bad_system_files_name_the_key_the_value_and_what_is_allowed(tmp_path, text, needles):
    path = write(tmp_path, text)
    with pytest.raises(SystemFileError) as info:
        load_system(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    for needle in needles:
        assert needle in message, message


def test_a_pose_outside_the_geometry_is_refused(tmp_path):
    # a wide lens looking almost level at 50 m: the far rows (the sky, ground beyond the reach) are simply
    # unreachable, the near ones plan
    path = write(tmp_path, "[camera]\nsensor_width_mm = 13.2\nhfov_deg = 120\npitch_deg = 6\n")
    geometry = system_build.core_config(load_system(path)).geometry(3840, 2160)
    assert geometry.unreachable_stripes == 8 and geometry_problem(geometry) is None
    # the same camera at 200 m sees no ground within the 90 m reach: a system that could never land is refused
    path = write(tmp_path, "[camera]\nsensor_width_mm = 13.2\nhfov_deg = 120\nheight_m = 200\npitch_deg = 6\n")
    with pytest.raises(SystemFileError, match=r"uav-el.toml: camera: .* has no stripe within the 90 m reach "
                                              r"\(the nearest ground in view lies 166 m ahead\).*raise pitch_deg"):
        load_system(path)
    # a reachable row looking less than 3 degrees down (a reach far beyond the horizon's ground, and a roll):
    # refused with the pitch that plans
    wide = replace(geometry, reach_m=10_000.0)
    assert geometry_problem(wide) is None  # the stripes are cut 3 degrees below the horizon
    assert "allowed: pitch_deg >= " in geometry_problem(wide, roll_deg=5.0)


def test_a_model_whose_hash_differs_from_the_file_is_refused(tmp_path):
    (tmp_path / "net.pt").write_bytes(b"not really weights")
    path = write(tmp_path, '[model]\npath = "net.pt"\nsha256 = "' + "0" * 64 + '"\n')
    with pytest.raises(SystemFileError, match="model.sha256: .*net.pt has SHA-256"):
        load_system(path)


def test_the_schema_is_packaged_and_closed():
    s = schema()
    assert s["additionalProperties"] is False
    assert set(s["properties"]) >= {"model", "camera", "labels", "safety", "monitor", "data", "targets",
                                    "waivers", "report"}


@pytest.fixture
def land(monkeypatch):
    monkeypatch.setattr(cli, "COMMANDS", {"land": "land"})
    return cli.main


def test_land_reads_the_system_file_and_options_win(land, scene, tmp_path, capsys):
    labels, _ = scene
    system = write(tmp_path, "[camera]\nheight_m = 30\npitch_deg = 60\n[safety]\nradius_m = 3\n")
    out = tmp_path / "d.json"
    assert land(["land", "--labels", str(labels), "--system", str(system), "--json", str(out)]) == 0
    core = json.loads(out.read_text())["config"]["core"]
    assert core["pose"] == {"height_m": 30, "pitch_deg": 60} and core["safety"]["radius_m"] == 3
    assert land(["land", "--labels", str(labels), "--system", str(system), "--height", "40", "--json", str(out)]) == 0
    d = json.loads(out.read_text())  # the option wins for the frame, recorded as the command line's pose
    assert d["input"]["pose"]["height_m"] == 40 and d["input"]["pose"]["source"] == "command_line"


def test_a_bad_system_file_is_exit_2_with_one_line_and_nothing_written(land, scene, tmp_path, capsys):
    labels, _ = scene
    system = write(tmp_path, "[camera]\nheigth_m = 30\n")
    out = tmp_path / "d.json"
    assert land(["land", "--labels", str(labels), "--system", str(system), "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unknown key camera.heigth_m" in err
    assert not out.exists()


def test_a_system_file_in_the_working_directory_is_found(land, scene, tmp_path, monkeypatch):
    labels, _ = scene
    write(tmp_path, "[camera]\nheight_m = 25\n")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "d.json"
    assert land(["land", "--labels", str(labels), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["config"]["core"]["pose"]["height_m"] == 25


def test_missing_system_file(land, scene, tmp_path, capsys):
    labels, _ = scene
    assert land(["land", "--labels", str(labels), "--system", str(tmp_path / "nope.toml")]) == 2
    assert "nope.toml: no such system file" in capsys.readouterr().err


def test_land_on_semantic_drone_labels_keeps_clear_of_unlabelled_ground(land, tmp_path):
    from el.classes.labels import load_label_set

    sdd = load_label_set("semantic_drone")
    ids = np.full((H, W), sdd.ids["grass"], dtype=np.uint8)
    ids[:, :90] = sdd.ignore.id  # unlabelled: unknown ground
    ids[70:74, :] = sdd.ids["paved-area"]
    labels = tmp_path / "sdd.png"
    write_labels(labels, ids, sdd)
    system = write(tmp_path, '[labels]\npreset = "semantic_drone"\n[camera]\nheight_m = 20\npitch_deg = 80\n'
                             '[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n')  # a small test frame
    out = tmp_path / "d.json"
    assert land(["land", "--labels", str(labels), "--system", str(system), "--json", str(out)]) == 0
    decision = json.loads(out.read_text())
    assert decision["candidates"], "grass on the right leaves room to land"
    for c in decision["candidates"]:
        assert c["x"] - c["radius_px"] >= 90 - 1, c  # no disc reaches into the unlabelled strip


def test_el_r14_is_judged_at_every_pose_a_run_planned_at():
    from assurance.requirements.checks import check_pose_margins
    from assurance.requirements.records import FAIL, PASS

    core = CoreConfig().to_dict()
    safety = {"radius_m": 2.0, "beta": 1.7}
    one = check_pose_margins(core, (3840, 2160), [], {"height": 0.2, "pitch": 0.2}, safety)
    many = check_pose_margins(core, (3840, 2160), [(30.0, 60.0), (80.0, 35.0)], {"height": 0.2, "pitch": 0.2}, safety)
    assert one.status == PASS and len(one.rows) == 1
    assert len(many.rows) == 3 and "worst of 3 poses" in many.summary
    # a frame flown far lower and flatter than the nominal pose needs a larger beta over the rows it plans on
    # (at 5 m every stripe is within reach): the requirement fails on it
    worst = check_pose_margins(core, (3840, 2160), [(5.0, 20.0)], {"height": 0.2, "pitch": 0.2}, safety)
    assert worst.status == FAIL and "required 2.103" in worst.summary
    # the core's reach_m decides which rows are judged: at 50 m and 15 degrees the far rows needing a larger
    # beta are out of the default 90 m reach (never planned on), within a 10 km one
    flat = [(50.0, 15.0)]
    assert check_pose_margins(core, (3840, 2160), flat, {"height": 0.2, "pitch": 0.2}, safety).status == PASS
    far = check_pose_margins({**core, "reach_m": 10_000.0}, (3840, 2160), flat, {"height": 0.2, "pitch": 0.2}, safety)
    assert far.status == FAIL and "required 1.930" in far.summary
    # a frame seeing no ground within reach plans nothing: no radius at risk, nothing to fail
    high = check_pose_margins(core, (3840, 2160), [(200.0, 20.0)], {"height": 0.2, "pitch": 0.2}, safety)
    assert high.status == PASS and high.rows[-1]["required_beta"] == 1.0
