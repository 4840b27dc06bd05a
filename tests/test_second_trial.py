"""Issue 60, a user's own system tried a second time: a ``[data]`` table whose path climbs out of the system file's
folder (``../raw``, as docs/system-file.md writes it) works for the campaign as for preview; a perturbation's noise is
keyed by the frame's pixels, not the layout's folder names (the same frames read through two layouts get the same
noise and the same decisions); a plugin network named by ``[model] classes`` flies with a frame gate (its frame
statistics asked for through the wrapper)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import scene_ids

from assurance import cli
from assurance.campaign import readouts
from assurance.campaign.task import frame_identity, task_seed
from assurance.dataio.uavid import write_image
from el.classes.labels import UAVID, load_label_set

DRONE = load_label_set("semantic_drone")
TO_DRONE = {"road": "paved-area", "building": "roof", "static_car": "car", "moving_car": "car", "tree": "tree",
            "low_vegetation": "grass", "human": "person", "clutter": "gravel"}


def _frames(root: Path, n: int = 3, images: str = "original_images", labels: str = "label_images_semantic") -> None:
    """Semantic Drone frames (JPEG, grey ids + 1) of scene_ids, at 256x144."""
    lut = np.array([DRONE.names.index(TO_DRONE[n]) for n in UAVID.names], np.uint8)
    for i in range(n):
        ids = scene_ids(256, 144, seed=i)
        write_image(root / images / f"{i:03d}.jpg", UAVID.ids_to_colors(ids))
        (root / labels).mkdir(parents=True, exist_ok=True)
        assert cv2.imwrite(str(root / labels / f"{i:03d}.png"), lut[ids] + 1)


def _system(folder: Path, data: str) -> Path:
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_DRONE.items())
    unreachable = [n for n in DRONE.names if n not in TO_DRONE.values()]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "uav-el.toml"
    path.write_text(f'format = "uav-el-system/1"\n[labels]\npreset = "semantic_drone"\n'
                    f'[model]\nclass_map = {{ {class_map} }}\nunreachable = {json.dumps(unreachable)}\n'
                    f'[monitor]\nspec = "lhd"\n{data}', "utf-8")
    return path


def _decisions(run: Path) -> dict[str, tuple]:
    images = readouts.load_table(run, "images")
    return {(r.frame, r.perturbation, r.monitor): (r.action, r.selected, r.reason) for r in images.itertuples()}


@pytest.mark.parametrize("spelling", ["climbs", "absolute", "below"])
def test_a_data_table_path_is_read_alike_by_every_command(spelling, tmp_path, capsys):
    raw = tmp_path / "raw"
    _frames(raw)
    sys_dir = tmp_path / "sys" if spelling != "below" else tmp_path
    path = {"climbs": "../raw", "absolute": str(raw), "below": "raw"}[spelling]
    system = _system(sys_dir, f'[data.test]\npath = "{path}"\nlayout = "semantic-drone"\n')
    assert cli.main(["preview", "--system", str(system), "--out", str(tmp_path / "p.png"), "--width", "64"]) == 0
    run = tmp_path / "run"
    code = cli.main(["campaign", "--system", str(system), "--out", str(run), "--perturbations", "none",
                     "--monitors", "lhd", "--quiet"])
    assert code == 0, capsys.readouterr().err
    man = json.loads((run / "manifest.json").read_text())
    assert man["data"]["images"] == 3 and man["data"]["spec"]["path"] == str(raw.resolve())


def test_the_same_frames_through_two_layouts_get_the_same_noise_and_decisions(tmp_path, capsys):
    a, b = tmp_path / "sdd", tmp_path / "mine"
    _frames(a)
    shutil.copytree(a / "original_images", b / "flight-7" / "rgb")  # the same files, other folder names
    shutil.copytree(a / "label_images_semantic", b / "flight-7" / "ids")
    tables = {a: 'layout = "semantic-drone"',
              b: 'images = "flight-7/rgb/*.jpg"\nlabels = "flight-7/ids/{stem}.png"\nlabel_encoding = "ids"\n'
                 'id_offset = 1'}
    runs = []
    for root, table in tables.items():
        system = _system(tmp_path / f"sys-{root.name}", f'[data.test]\npath = "{root}"\n{table}\n')
        run = tmp_path / f"run-{root.name}"
        assert cli.main(["campaign", "--system", str(system), "--out", str(run), "--perturbations", "gaussian_noise",
                         "--severities", "3", "--monitors", "lhd", "--quiet"]) == 0, capsys.readouterr().err
        runs.append(run)
    keys = [sorted(set(readouts.load_table(r, "images")["key"])) for r in runs]
    assert keys[0] != keys[1]  # two layouts: other keys ...
    assert _decisions(runs[0]) == _decisions(runs[1])  # ... the same decisions under the same noise
    rgb = np.zeros((4, 5, 3), np.uint8)
    assert task_seed(0, frame_identity(rgb), "gaussian_noise", 3) != task_seed(0, frame_identity(rgb + 1),
                                                                                "gaussian_noise", 3)
    assert frame_identity(rgb) != frame_identity(rgb.reshape(5, 4, 3))  # the shape is part of what a frame is


def test_a_plugin_network_named_by_classes_passes_frame_statistics_on():
    from assurance.system.model import NamedChannels
    from el.segmentation.contract import FRAME_STATS, OutputClasses, has_capability, segment_frame

    class WithStats:
        frame_stats = True

        def predict_frame(self, rgb, stats=False):
            probs = np.full((3, *rgb.shape[:2]), 1 / 3, np.float32)
            return (probs, {"energy": 1.5}) if stats else probs

        def predict_patch(self, rgb_patch, **kwargs):
            return np.full((3, *rgb_patch.shape[:2]), 1 / 3, np.float32)

    named = NamedChannels(WithStats(), OutputClasses("mine", ("a", "b", "c")))
    assert has_capability(named, FRAME_STATS)
    found = segment_frame(named, np.zeros((8, 8, 3), np.uint8), stats=True)  # raised TypeError before
    assert found.stats == {"energy": 1.5} and found.probs.shape == (3, 8, 8)


def test_a_capped_perturbation_is_said_at_the_severity_it_ran():
    """The trial's gaussian_noise = 2 ran at severity 2: the report said 'at severity 3' and 'severities not
    evaluated: 1, 2, 4, 5'."""
    from assurance.evidence.sections import perturbations_text, run_scenarios

    cfg = {"perturbations": ["none", "fog", "gaussian_noise"], "severities": [3],
           "severity_caps": {"gaussian_noise": 2}}
    assert perturbations_text(cfg) == "none, fog at severity 3; gaussian_noise at severity 2 (its declared maximum)"
    assert {s for _, s in run_scenarios(cfg)} == {2, 3}


def test_evidence_without_system_says_when_the_runs_file_has_changed(tmp_path, monkeypatch, capsys):
    raw = tmp_path / "raw"
    _frames(raw, n=2)
    system = _system(tmp_path / "sys", '[data.test]\npath = "../raw"\nlayout = "semantic-drone"\n')
    run = tmp_path / "run"
    assert cli.main(["campaign", "--system", str(system), "--out", str(run), "--perturbations", "none",
                     "--monitors", "lhd", "--quiet"]) == 0
    monkeypatch.chdir(tmp_path)  # no uav-el.toml here: the run's own is judged
    args = ["evidence", "--run", str(run), "--out", str(tmp_path / "r"), "--no-pdf", "--boot", "20"]
    capsys.readouterr()
    cli.main(args)
    assert "has changed since the run" not in capsys.readouterr().out
    system.write_text(system.read_text("utf-8") + "[targets]\ntime_budget_s = 20\n", "utf-8")
    cli.main(args)
    out = capsys.readouterr().out
    assert "(the run's own)" in out and f"note: {system} has changed since the run" in out, out
    monkeypatch.chdir(system.parent)  # the edited file is uav-el.toml here: the run's recorded copy is still judged
    cli.main(args)
    out = capsys.readouterr().out
    assert "(the run's own)" in out and "in the working directory is not the run's system file" in out, out


def test_an_acceptance_names_a_class_as_class_names_are_compared():
    """--accept-deviation class:strasse=safe accepts the deviation class:Straße (NFKC, case-folded: one name);
    another class is still no deviation of the system's."""
    from assurance.requirements.basis import Deviation, _offers
    from el.classes.class_names import pinned_category

    found = [Deviation("class:Straße", "forbidden", "safe", value="safe"), Deviation("unsafe_landing_bound", 0.05, 0.1)]
    assert _offers(["class:strasse=safe", "unsafe_landing_bound=0.1"], found) == {
        "class:Straße": "safe", "unsafe_landing_bound": "0.1"}
    with pytest.raises(ValueError, match="does not deviate"):
        _offers(["class:weg=safe"], found)
    with pytest.raises(ValueError, match="here: --accept-deviation class:Straße=safe"):
        _offers(["class:STRASSE"], found)
    assert pinned_category("Haus") == "building" and pinned_category("Mensch") == "person"  # the trial's names


def test_preview_checks_the_poses_file_as_the_campaign_does(tmp_path, capsys):
    raw = tmp_path / "raw"
    _frames(raw, n=2)
    (raw / "poses.csv").write_text("frame,height_m,pitch_deg\n000,20,90\n099,20,90\n", "utf-8")
    system = _system(tmp_path / "sys", '[data.test]\npath = "../raw"\nlayout = "semantic-drone"\nposes = "poses.csv"\n')
    assert cli.main(["preview", "--system", str(system), "--out", str(tmp_path / "p.png"), "--width", "64"]) == 2
    err = capsys.readouterr().err
    assert "poses.csv: frame '099' has no image" in err and err.count("\n") == 1, err


def test_land_to_a_log_in_no_folder_is_one_line(tmp_path, capsys):
    raw = tmp_path / "raw"
    _frames(raw, n=1)
    system = _system(tmp_path / "sys", "")
    code = cli.main(["land", str(raw / "original_images" / "000.jpg"), "--system", str(system), "--height", "20",
                     "--pitch", "90", "--log", str(tmp_path / "no" / "such" / "flight.jsonl")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no folder" in err, err


def test_fit_gate_warns_when_its_quantile_is_the_validation_maximum():
    """The trial's gate: the 0.997 quantile of 8 validation frames is their maximum and refused 4 of 12 clean
    frames in the campaign: fit-gate says so."""
    from assurance.cli.fit_gate import too_few_frames

    assert "at least 334 frames" in too_few_frames(0.997, 8)
    assert too_few_frames(0.997, 334) is None and too_few_frames(0.9, 10) is None


def test_the_gallery_shows_each_perturbation_at_a_severity_it_ran():
    """A system declaring fog up to 2 ran fog at severity 2: the gallery said 'fog, severity 3'."""
    import numpy as np

    from assurance.evidence.gallery import perturbation_gallery

    class Frames:
        samples = {"seq00/000000": None}
        asked: list[tuple[str, int]] = []

        def image(self, key, name, severity):
            self.asked.append((name, severity))
            return np.zeros((8, 8, 3), np.uint8)

    frames = Frames()
    shown = perturbation_gallery(frames, "seq00/000000", [("none", 3), ("fog", 2), ("fog", 1), ("motion_blur", 3)])
    assert [g["caption"] for g in shown] == ["none (unperturbed)", "fog, severity 2", "motion_blur, severity 3"]
    assert frames.asked == [("none", 3), ("fog", 2), ("motion_blur", 3)]


def test_a_default_action_outside_the_domain_is_not_told_as_the_monitors_rejection():
    """Every frame of an auditor's trial was refused outside the declared domain; the card said 'all 2 of 11
    candidates rejected' where the monitor had accepted an unsafe one."""
    import pandas as pd

    from assurance.evidence.gallery import walk_summary

    cands = pd.DataFrame({"rank": [0, 1, 2, 3], "examined": [True, True, True, False],
                          "accepted": [False, False, True, False], "reason": ["asphalt", "vehicle", "ok", ""]})
    line = walk_summary(cands, -1, "outside_odd: image_width 320 px not in [1920, 1920] px")
    assert line.startswith("the default action before any landing (outside_odd)") and "1 accepted" in line, line
    assert walk_summary(cands, -1, "all_rejected").startswith("all 2 of 4 candidates rejected")


def test_every_command_takes_no_progress(tmp_path, monkeypatch, capsys):
    """fit-gate, fit-verifier and synth had --no-progress, fit-monitor and calibrate did not: every command takes it
    now, and it turns the progress bars off for the command (worker processes included: the environment)."""
    import os

    from assurance import cli

    for command in ("fit-monitor", "calibrate", "fit-gate", "campaign", "evidence", "verify"):
        try:
            code = cli.main([command, "--no-progress", "--system", str(tmp_path / "none.toml")])
        except SystemExit as stop:  # argparse: a required option missing (never --no-progress unknown)
            code = stop.code
        assert code == 2 and "unrecognized arguments" not in capsys.readouterr().err, command
    monkeypatch.delenv("UAV_EL_PROGRESS", raising=False)
    with cli._no_progress(True):
        assert os.environ["UAV_EL_PROGRESS"] == "none"
    assert "UAV_EL_PROGRESS" not in os.environ
