"""The system's declared perturbations drive the work (``assurance.campaign.perturbation_plan``): the presets run
``none``, the declared ``[odd] perturbations`` and the required ones; one outside the declared domain runs only when
asked (or required), said and marked in the manifest and the report; fit-gate and calibrate use the declared ones;
the shipped default keeps the paper's six, so its release run does not move."""

from __future__ import annotations

import json

import pytest
from conftest import TINY_H, TINY_W, TINY_WW, tiny_scene
from helpers import OracleSegmenter

from assurance.campaign.perturbation_plan import (
    domain_record,
    fit_levels,
    outside_lines,
    outside_scenarios,
    system_plan,
)
from assurance.campaign.presets import preset_config
from assurance.perturbations import PAPER_PERTURBATIONS
from assurance.system import default_system, load_system
from assurance.system.system import System

SYSTEM = """format = "uav-el-system/1"
[system]
name = "noisy drone"
[odd]
image_width = [200, 300]
image_height = [100, 200]
aspect = [1.5, 2.0]
perturbations = {{ gaussian_noise = {level} }}
[monitor]
spec = "lhd"
[targets]
required_perturbations = ["gaussian_noise"]
min_images_per_perturbation = 2
"""


def _system(tmp_path, level: int = 3, extra: str = "") -> System:
    path = tmp_path / f"uav-el-{level}.toml"
    path.write_text(SYSTEM.format(level=level) + extra)
    return System.build(load_system(path))


def test_the_shipped_default_plan_is_the_paper_six_and_the_release_preset_does_not_move():
    plan = system_plan()
    assert tuple(p.name for p in plan) == PAPER_PERTURBATIONS and all(p.inside for p in plan)
    assert all(p.severity == 3 for p in plan)
    assert system_plan(default_system()) == plan
    release = preset_config("release")
    assert release.perturbations == PAPER_PERTURBATIONS and release.severities == (3,) and release.images == 70
    assert release.severity_caps is None and "severity_caps" not in release.to_dict()
    severity = preset_config("severity")  # beyond the declared maxima, as before
    assert severity.perturbations == PAPER_PERTURBATIONS[1:] and severity.severities == (1, 2, 3, 4, 5)
    assert severity.severity_caps is None
    assert fit_levels(default_system()) is None  # the shipped gate and card are fitted as they were


def test_a_file_declaring_no_perturbations_inherits_the_six(tmp_path):
    path = tmp_path / "uav-el.toml"
    path.write_text('[system]\nname = "plain"\n[camera]\nheight_m = 60\n')
    system = System.build(load_system(path))
    assert tuple(p.name for p in system_plan(system)) == PAPER_PERTURBATIONS
    assert fit_levels(system) is None  # no declaration of its own: the commands' own defaults


def test_a_declared_domain_is_the_plan_and_the_presets_run_it(tmp_path):
    system = _system(tmp_path)
    plan = system_plan(system)
    assert [(p.name, p.severity, p.inside, p.required) for p in plan] == [
        ("none", 3, True, False), ("gaussian_noise", 3, True, True)]
    demo = preset_config("demo", plan=plan)
    assert demo.perturbations == ("none", "gaussian_noise") and demo.scenarios() == [
        ("none", 3), ("gaussian_noise", 3)]
    assert preset_config("severity", plan=plan).scenarios() == [("gaussian_noise", s) for s in range(1, 6)]
    assert preset_config("demo", plan=plan, perturbations=("fog",)).perturbations == ("fog",)  # the option wins
    assert fit_levels(system) == (("none", 3), ("gaussian_noise", 3))


def test_a_declared_maximum_below_three_caps_the_severity_unless_severities_are_given(tmp_path):
    system = _system(tmp_path, level=2)
    plan = system_plan(system)
    assert [(p.name, p.severity) for p in plan] == [("none", 3), ("gaussian_noise", 2)]
    demo = preset_config("demo", plan=plan)
    assert demo.severity_caps == {"gaussian_noise": 2}
    assert demo.scenarios() == [("none", 3), ("gaussian_noise", 2)]
    assert demo.to_dict()["severity_caps"] == {"gaussian_noise": 2}
    asked = preset_config("demo", plan=plan, severities=(3,))
    assert asked.severity_caps is None and asked.scenarios() == [("none", 3), ("gaussian_noise", 3)]
    record = domain_record(asked.perturbations, asked.scenarios(), system.odd)
    assert record["gaussian_noise"] == {"declared_max": 2, "severities": [3], "inside": False}
    assert fit_levels(system) == (("none", 3), ("gaussian_noise", 2))


def test_a_required_perturbation_outside_the_domain_runs_marked_outside(tmp_path):
    system = _system(tmp_path, extra="")
    path = tmp_path / "required.toml"
    path.write_text(SYSTEM.format(level=3).replace('["gaussian_noise"]', '["none", "fog", "gaussian_noise"]'))
    required = System.build(load_system(path))
    plan = system_plan(required)
    assert [(p.name, p.inside) for p in plan] == [("none", True), ("fog", False), ("gaussian_noise", True)]
    config = preset_config("demo", plan=plan, odd=required.odd.to_dict())
    lines = outside_lines(domain_record(config.perturbations, config.scenarios(), config.odd), plan, "x.toml")
    assert len(lines) == 1 and lines[0].startswith("fog is outside the declared operating domain of x.toml")
    assert "required by [targets] required_perturbations" in lines[0]
    basis = outside_lines(domain_record(config.perturbations, config.scenarios(), config.odd), plan, "x.toml",
                          own_required=False)  # a file that sets none is held to the registry's: it says so
    assert "required by the certification basis" in basis[0] and "[targets]" not in basis[0]
    assert fit_levels(required) == (("none", 3), ("gaussian_noise", 3))  # the gate and card: inside ones only
    assert system_plan(system) != plan


def test_fit_gate_frames_use_the_declared_perturbations(tmp_path):
    import numpy as np
    from PIL import Image

    from assurance.fitting.gate_frames import training_frames, validation_frames

    paths = []
    for i in range(2):
        p = tmp_path / f"{i}.png"
        Image.fromarray(np.full((24, 32, 3), 90 + 40 * i, np.uint8)).save(p)
        paths.append(p)
    shipped = [name for _, name, _ in training_frames(paths[:1])]
    assert [n.split(":")[0] for n in shipped] == list(PAPER_PERTURBATIONS) + list(PAPER_PERTURBATIONS[1:])
    mine = list(training_frames(paths, levels=(("none", 3), ("gaussian_noise", 2))))
    assert [name for i, name, _ in mine if i == 0][1:] == [mine[1][1], "gaussian_noise:2"]
    assert {name.split(":")[0] for _, name, _ in mine} == {"none", "gaussian_noise"}
    assert all(int(name.split(":")[1]) <= 2 for _, name, _ in mine if name.startswith("gaussian"))
    assert not np.array_equal(mine[1][2], mine[0][2])  # perturbed, not the clean frame
    held = [name for _, name, _ in validation_frames([(0, paths[0])], (3,), levels=(("gaussian_noise", 2),))]
    assert held == ["none:0", "gaussian_noise:2"]


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    from assurance.dataio.uavid import write_sample
    from el.classes.labels import UAVID, ids_to_colors

    root = tmp_path_factory.mktemp("declared") / "data"
    for i in range(2):
        ids = tiny_scene(i)
        assert ids.shape == (TINY_H, TINY_W)
        write_sample(root, "seq00", f"{i:06d}", ids_to_colors(ids), ids, labels=UAVID)
    return root


def _campaign(system: System, data, out, **overrides):
    from assurance.campaign.run import Execution, run_campaign
    from assurance.system import build as system_build

    core = system_build.core_config(system.file, n_star=6, working_width=TINY_WW)
    config = preset_config("demo", plan=system_plan(system), monitors=("lhd",), core=core,
                           odd=system.odd.to_dict(), **overrides)
    summary = run_campaign(data, out, config, segmenter=OracleSegmenter(TINY_WW),
                           system=system.file, signing_key=False, execution=Execution(progress=False))
    assert summary["faults"] == []
    return config


def test_a_tiny_campaign_runs_the_declared_perturbations_and_verifies_el_r08(tiny_data, tmp_path):
    from assurance import requirements as rq
    from assurance.campaign import readouts
    from assurance.requirements.campaign_checks import perturbation_coverage

    system = _system(tmp_path)
    run = tmp_path / "run"
    _campaign(system, tiny_data, run)
    images = readouts.load_table(run, "images")
    assert set(zip(images["perturbation"], images["severity"], strict=True)) == {("none", 3), ("gaussian_noise", 3)}
    man = json.loads((run / "manifest.json").read_text())
    assert {p: r["inside"] for p, r in man["perturbation_domain"].items()} == {"none": True, "gaussian_noise": True}
    reg = rq.load_registry(targets=system.targets)
    assert reg.parameters["required_perturbations"] == ["gaussian_noise"]
    evidence = perturbation_coverage(rq.CheckContext(run, reg.parameters))
    assert evidence.status == rq.PASS, evidence.summary


def test_an_asked_perturbation_outside_the_domain_runs_and_is_marked(tiny_data, tmp_path):
    from assurance.analysis.table import results_table
    from assurance.evidence.domain_section import OUTSIDE_MARK, mark_outside
    from assurance.evidence.sections import results_view

    system = _system(tmp_path)
    run = tmp_path / "fog"
    config = _campaign(system, tiny_data, run, perturbations=("none", "fog"), images=1)
    assert config.scenarios() == [("none", 3), ("fog", 3)]
    man = json.loads((run / "manifest.json").read_text())
    assert man["perturbation_domain"]["fog"] == {"declared_max": None, "severities": [3], "inside": False}
    assert man["perturbation_domain"]["none"]["inside"] is True
    assert outside_scenarios(man) == {("fog", 3)}
    lines = outside_lines(man["perturbation_domain"], system_plan(system), system.label)
    assert len(lines) == 1 and "fog is outside" in lines[0] and "(asked for)" in lines[0]
    table = results_table(run, n_boot=20)
    view = mark_outside(results_view(table, "lhd", 0.05, 0.95), table, man)
    marked = [r["scenario"] for r in view["rows"] if r["scenario"]]
    assert marked == ["none (s3)", f"fog (s3) {OUTSIDE_MARK}"]


def test_calibration_scores_the_declared_perturbations_too(tiny_data):
    from helpers import nearest_class

    from assurance.fitting.calibration import CalibrationScenes, ThresholdRule, calibrate_on_data
    from el.classes.labels import ids_to_colors
    from el.geometry.config import CoreConfig

    class RoadBlindFrame(OracleSegmenter):
        """Frames: road seen as low vegetation (candidates land on the road); patches: perfect."""

        def predict_frame(self, rgb):
            ids = nearest_class(rgb)
            ids[ids == 2] = 5
            return super().predict_frame(ids_to_colors(ids))

    def card(perturbations):
        scenes = CalibrationScenes(core=CoreConfig(n_star=6, working_width=TINY_WW), perturbations=perturbations)
        return calibrate_on_data(tiny_data, "lhd", rule=ThresholdRule(miss_rate=0.5, confidence=0.5), scenes=scenes,
                                 segmenter=RoadBlindFrame(TINY_WW))["body"]

    clean, declared = card(None), card((("none", 3), ("gaussian_noise", 2)))
    assert clean["split"]["perturbation"] == "none"  # the shipped card's record, as before
    assert declared["split"]["perturbation"] == "none, gaussian_noise s2"
    assert declared["split"]["images"] == clean["split"]["images"] == 2  # scenes, not tasks
    assert declared["split"]["sha256"] == clean["split"]["sha256"]
    assert declared["counts"]["candidates"] > clean["counts"]["candidates"]  # the noisy frames' candidates too


def test_the_campaign_command_says_an_asked_perturbation_is_outside(tiny_data, tmp_path, capsys):
    """``uav-el campaign --perturbations none fog`` on a system declaring only gaussian_noise: fog runs, one line
    says it is outside the declared domain, and the manifest marks it; the declared run names no such line."""
    import torch

    from assurance import cli
    from assurance.fitting.network.weights_io import save_weights
    from el.segmentation.architectures import build_model
    from el.segmentation.model import ArchConfig

    torch.manual_seed(0)
    save_weights(build_model(ArchConfig(widths=(8, 8, 8), decoder_channels=8)), tmp_path / "tiny.pt")
    path = tmp_path / "uav-el.toml"
    path.write_text(SYSTEM.format(level=3).replace("[monitor]", '[model]\npath = "tiny.pt"\nworking_width = '
                                                   f'{TINY_WW}\n[data]\ntest = "{tiny_data}"\n[monitor]'))
    argv = ["campaign", "--system", str(path), "--monitors", "lhd", "--images", "1", "--quiet"]
    assert cli.main([*argv, "--out", str(tmp_path / "fog"), "--perturbations", "none", "fog"]) == 0
    said = capsys.readouterr().err
    assert "uav-el campaign: fog is outside the declared operating domain of" in said and "(asked for)" in said
    man = json.loads((tmp_path / "fog" / "manifest.json").read_text())
    assert {p: r["inside"] for p, r in man["perturbation_domain"].items()} == {"none": True, "fog": False}
    assert cli.main([*argv, "--out", str(tmp_path / "declared")]) == 0
    assert "outside the declared operating domain" not in capsys.readouterr().err
    man = json.loads((tmp_path / "declared" / "manifest.json").read_text())
    assert man["config"]["perturbations"] == ["none", "gaussian_noise"]
