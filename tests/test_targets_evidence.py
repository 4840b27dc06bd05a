"""The requirement targets end to end on the tiny campaign run: the pytest plugin judges with a targets file, the
evidence report shows the targets and the bound at their confidence, and the gate refuses a report on other
targets (``uav-el evidence --targets``)."""

from __future__ import annotations

import json

import hypothesis  # noqa: F401  # imported once here: pytester's in-process runs would re-import it every time
import pytest

from assurance import cli
from assurance import requirements as rq
from assurance.evidence import generate
from assurance.requirements.suite import SUITE_DIR

pytest_plugins = ["pytester"]

CAMPAIGN_TESTS = SUITE_DIR / "test_campaign_requirements.py"
TARGETS = {"deployed_monitor": "lhd", "calibration_card": None, "unsafe_landing_bound": 0.3, "confidence": 0.99}


@pytest.fixture
def judged(pytester, tiny_campaign, tmp_path):
    """(run, targets file, requirement results judged with it)."""
    tfile = tmp_path / "targets.json"
    tfile.write_text(json.dumps(TARGETS))
    results = tmp_path / "requirements.json"
    pytester.runpytest(str(CAMPAIGN_TESTS), "-p", "no:cacheprovider", "--uav-el-run", str(tiny_campaign["run"]),
                       "--requirements-report", str(results), "--uav-el-targets", str(tfile),
                       "-k", "unsafe_landing_bound or safety_gain")
    from assurance.attest.keys import load_signing_key
    from assurance.requirements.attestation import sign_session_results
    from assurance.system.build import shipped_waivers

    # as uav-el verify --targets would
    sign_session_results(tiny_campaign["run"], tmp_path, load_signing_key(), waivers=shipped_waivers())
    return tiny_campaign["run"], tfile, results


def test_report_on_the_same_targets_shows_them_and_the_bound_at_their_confidence(judged, tmp_path):
    run, tfile, results = judged
    doc = json.loads(results.read_text())
    assert doc["registry"]["targets"] == TARGETS
    rep = generate(run, tmp_path / "same", requirements=results, targets=rq.read_targets_file(tfile),
                   targets_source=str(tfile.resolve()), pdf=False, n_boot=50)
    assert not [p for p in rep.problems if "requirement targets" in p], rep.problems
    html = rep.html.read_text(encoding="utf-8")
    assert "UB99" in html and "UB95" not in html and "one-sided 99% upper bound" in html
    assert "Requirement targets" in html and "confidence = 0.99" in html
    assert "shown with 99% confidence" in html  # EL-R10's text rendered from the targets
    ev = json.loads(rep.json.read_text())
    assert ev["identity"]["targets"] == TARGETS and ev["parameters"]["confidence"] == 0.99
    assert ev["identity"]["parameters_sha256"] == doc["registry"]["parameters_sha256"]
    r10 = ev["checks"]["EL-R10"]
    assert r10["status"] == rq.INSUFFICIENT and "99% confidence" in r10["name"]
    assert {row["confidence"] for row in r10["rows"]} == {"99%"}
    assert "uav-el verify" in html and f"--targets {tfile.resolve()}" in html


def test_report_on_other_targets_fails_the_gate(judged, tmp_path, monkeypatch, capsys):
    run, tfile, results = judged
    rep = generate(run, tmp_path / "other", requirements=results, pdf=False, n_boot=50)  # registry defaults
    assert rep.exit_code == 1
    assert any("judged on other requirement targets" in p and '"confidence": 0.99' in p for p in rep.problems)
    # the command line: --targets binds the report to the same targets; a bad file is one line, exit 2
    monkeypatch.setitem(cli.COMMANDS, "evidence", "evidence")
    code = cli.main(["evidence", "--run", str(run), "--out", str(tmp_path / "cli"), "--requirements", str(results),
                     "--targets", str(tfile), "--no-pdf", "--boot", "50"])
    out = capsys.readouterr().out  # bound to the same targets; weaker than the system's, and deselected ones block
    problems = [line for line in out.splitlines() if line.startswith("gate problem")]
    assert "other requirement targets" not in out and code == 1
    assert problems and all("weaker than the system's requirements" in p for p in problems)
    assert any("parameter unsafe_landing_bound = 0.3 is higher (looser) than the system's 0.05" in p
               for p in problems)
    bad = tmp_path / "bad.json"
    bad.write_text('{"confidence": 2}')
    assert cli.main(["evidence", "--run", str(run), "--out", str(tmp_path / "bad"), "--targets", str(bad),
                     "--no-pdf"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.json.confidence = 2" in err[0] and "[0.5, 1)" in err[0]


def test_a_system_files_targets_bind_the_report(pytester, tiny_campaign, tmp_path):
    """generate(system=...) judges with the system file's [targets] (assurance.system.build.targets): results
    judged on the same targets pass the binding, the registry's defaults do not."""
    from assurance.system import build as system_build
    from assurance.system import load_system

    sysfile = tmp_path / "uav-el.toml"
    sysfile.write_text("[targets]\nconfidence = 0.99\nunsafe_landing_bound = 0.3\n")
    system = load_system(sysfile)
    targets = system_build.targets(system)
    assert targets == {"confidence": 0.99, "unsafe_landing_bound": 0.3}
    tfile = tmp_path / "t.json"
    tfile.write_text(json.dumps(targets))
    results = tmp_path / "requirements.json"
    pytester.runpytest(str(CAMPAIGN_TESTS), "-p", "no:cacheprovider", "--uav-el-run", str(tiny_campaign["run"]),
                       "--requirements-report", str(results), "--uav-el-targets", str(tfile), "-k", "coverage")
    rep = generate(tiny_campaign["run"], tmp_path / "sys", requirements=results, system=system, pdf=False, n_boot=50)
    assert not [p for p in rep.problems if "requirement targets" in p], rep.problems
    ev = json.loads(rep.json.read_text())
    assert ev["identity"]["targets"] == targets and ev["identity"]["targets_source"].endswith("[targets]")
    assert "bound 0.3 at 99% confidence" in ev["checks"]["EL-R10"]["name"]
    rep = generate(tiny_campaign["run"], tmp_path / "plain", requirements=results, pdf=False, n_boot=50)
    assert any("judged on other requirement targets" in p for p in rep.problems)
