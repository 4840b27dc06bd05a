"""A campaign records the system file it assessed; the evidence report shows it (hash, every value it sets, the
network's hash) and its gate refuses a run or requirement results about another system file."""

import json

import pytest
from conftest import TINY_WW
from helpers import OracleSegmenter

from assurance.campaign.run import CampaignConfig, Execution, run_campaign
from assurance.evidence import generate
from assurance.system import build as system_build
from assurance.system import default_system, load_system


@pytest.fixture(scope="module")
def system_run(tiny_campaign, tmp_path_factory):
    root = tmp_path_factory.mktemp("system_run")
    path = root / "uav-el.toml"
    path.write_text('[system]\nname = "test drone"\n[camera]\nheight_m = 60\n[report]\norganisation = "ACME"\n')
    system = load_system(path)
    core = system_build.core_config(system, n_star=6, working_width=TINY_WW)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), images=3, core=core)
    summary = run_campaign(tiny_campaign["data"], root / "run", config,
                           segmenter=OracleSegmenter(TINY_WW), system=system, execution=Execution(progress=False))
    assert summary["faults"] == []
    return {"run": root / "run", "system": system, "root": root}


def test_the_manifest_records_the_system_file_and_the_model_handed_in(system_run):
    man = json.loads((system_run["run"] / "manifest.json").read_text())
    assert man["system"]["sha256"] == system_run["system"].sha256
    assert man["system"]["document"]["camera"]["height_m"] == 60
    assert man["config"]["core"]["pose"]["height_m"] == 60
    # a model object handed to the campaign is named by its own hash, not the shipped weights'
    assert man["weights"]["sha256"] == OracleSegmenter.weights_sha256 and man["weights"]["path"] is None


def test_the_report_shows_the_system_and_its_gate_refuses_another(system_run, tmp_path):
    run, system = system_run["run"], system_run["system"]
    good = generate(run, tmp_path / "good", pdf=False, n_boot=50, system=system)
    assert not any("system file" in p for p in good.problems)
    html = good.html.read_text()
    assert system.sha256 in html and "camera.height_m" in html and "ACME" in html and "test drone" in html
    assert OracleSegmenter.weights_sha256 in html
    evidence = json.loads(good.json.read_text())
    assert evidence["identity"]["system_sha256"] == system.sha256

    other = generate(run, tmp_path / "other", pdf=False, n_boot=50, system=default_system())
    assert other.exit_code == 1
    assert any("another system file" in p for p in other.problems)


def test_requirement_results_of_another_system_file_are_refused(system_run, tmp_path):
    from assurance.evidence.context import system_problems

    man = json.loads((system_run["run"] / "manifest.json").read_text())
    doc = {"context": {"system_sha256": "f" * 64}}
    problems = system_problems(system_run["system"], man, doc, system_run["run"])
    assert problems and "not bound to the run's system file" in problems[0]
    ok = {"context": {"system_sha256": system_run["system"].sha256}}
    assert system_problems(system_run["system"], man, ok, system_run["run"]) == []


def test_a_system_files_section_templates_replace_the_packaged_ones_when_asked(system_run, tmp_path):
    tpl = system_run["root"] / "tpl"
    tpl.mkdir(exist_ok=True)
    (tpl / "section_limitations.html.j2").write_text("<section id='limitations'><p>ACME limits</p></section>")
    (tpl / "evidence.css").write_text("/* ACME house style */\n")  # never used: the stylesheet is the toolkit's
    path = system_run["root"] / "styled.toml"
    path.write_text(system_run["system"].path.read_text() + '\n[report]\ntemplates = "tpl"\n'
                    if "[report]" not in system_run["system"].path.read_text() else
                    system_run["system"].path.read_text().replace("[report]", '[report]\ntemplates = "tpl"'))
    styled = load_system(path)
    report = generate(system_run["run"], tmp_path / "styled", pdf=False, n_boot=50, system=styled,
                      requirements=None, system_templates=True)
    html = report.html.read_text()
    assert "ACME limits" in html and "What was assessed" in html  # the rest from the packaged templates
    assert "ACME house style" not in html and "<code>evidence.css</code>" in html
    assert any("another system file" in p for p in report.problems)  # a different file than the run's


def test_verify_and_evidence_without_system_judge_the_runs_own(system_run, tmp_path, monkeypatch, capsys):
    """Run from a folder holding no uav-el.toml, ``verify RUN`` binds the run's own system (its waivers: none here),
    not the shipped one's, and says so; ``evidence`` then finds no waivers mismatch."""
    from assurance import cli

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    out = tmp_path / "out"
    cli.main(["verify", str(system_run["run"]), "--out", str(out), "-k", "not rerun"])
    printed = capsys.readouterr()
    assert "system judged: " in printed.out and "(the run's own)" in printed.out
    assert "--system" not in printed.out  # the "next:" command needs none: evidence takes the run's own too
    doc = json.loads((out / "requirements.dsse.json").read_text())
    assert doc  # signed
    cli.main(["evidence", "--run", str(system_run["run"]), "--out", str(out), "--no-pdf", "--boot", "20"])
    assert "(the run's own)" in capsys.readouterr().out  # evidence says which system it judged too
    problems = json.loads((out / "evidence.json").read_text())["gate"]["problems"]
    assert not any("waivers" in p for p in problems), problems
