"""The run binding lives in the plugin: a user's own requirement test in a folder of its own (no conftest of this
project) is bound to the run and counted; options share the --uav-el- prefix (old names still work), ini options
give the defaults, and the plugin registers the campaign and slow markers."""

from __future__ import annotations

import json

import hypothesis  # noqa: F401  # imported once here: pytester's in-process runs would re-import it every time

from assurance import requirements as rq
from assurance.campaign.integrity import verify_run
from assurance.evidence.gate import binding_problems
from assurance.requirements.suite import SUITE_DIR

pytest_plugins = ["pytester"]

USER_TEST = """
import json
import pytest

@pytest.mark.requirements("EL-R12")
def test_my_own_check(campaign_run, requirement_registry):
    manifest = json.loads((campaign_run / "manifest.json").read_text())
    assert manifest["weights"]["sha256"]
    assert requirement_registry.parameters["confidence"] > 0
"""


def test_a_users_own_requirement_test_is_bound_to_the_run_and_counted(pytester, tiny_campaign):
    run = tiny_campaign["run"]
    pytester.makepyfile(test_mine=USER_TEST)
    out = pytester.path / "out" / "requirements.json"
    result = pytester.runpytest("-p", "no:cacheprovider", "-m", "requirements", "--uav-el-run", str(run),
                                "--uav-el-report", str(out))
    result.assert_outcomes(passed=1)
    doc = json.loads(out.read_text())
    ctx = doc["context"]
    assert ctx["run_digest"] == verify_run(run).digest
    assert ctx["system_sha256"] == json.loads((run / "manifest.json").read_text())["system"]["sha256"]
    assert ctx["code"]["sha256"] == ctx["code_sha256"]
    tests = doc["requirements"]["EL-R12"]["tests"]
    assert len(tests) == 1 and tests[0]["nodeid"].endswith("test_mine.py::test_my_own_check")
    assert doc["requirements"]["EL-R12"]["state"] == rq.VERIFIED
    reg = rq.load_registry()
    from assurance.code_identity import code_identity

    assert binding_problems(doc, verify_run(run).digest, code_identity()["sha256"], reg.sha256, out,
                            parameters_sha=reg.parameters_sha256) == []


def test_the_packaged_suite_and_a_users_test_in_one_session(pytester, tiny_campaign):
    run = tiny_campaign["run"]
    pytester.makepyfile(test_mine=USER_TEST)
    out = pytester.path / "requirements.json"
    result = pytester.runpytest("-p", "no:cacheprovider", "-m", "requirements", "--uav-el-run", str(run),
                                "--uav-el-report", str(out), "-k", "EL-R12 or my_own", "--rootdir", str(pytester.path),
                                str(SUITE_DIR / "test_campaign_requirements.py"), "test_mine.py")
    result.assert_outcomes(passed=2)
    ids = [t["nodeid"] for t in json.loads(out.read_text())["requirements"]["EL-R12"]["tests"]]
    assert len(ids) == 2 and any(i.endswith("test_mine.py::test_my_own_check") for i in ids)


def test_ini_options_give_the_run_and_the_report(pytester, tiny_campaign):
    pytester.makeini(f"[pytest]\nuav_el_run = {tiny_campaign['run']}\nuav_el_report = out/req.json\n")
    pytester.makepyfile(test_mine=USER_TEST)
    pytester.runpytest("-p", "no:cacheprovider").assert_outcomes(passed=1)
    doc = json.loads((pytester.path / "out" / "req.json").read_text())
    assert doc["context"]["run_digest"] == verify_run(tiny_campaign["run"]).digest


def test_without_a_run_a_users_test_is_not_verified_and_unbound(pytester, tmp_path):
    pytester.makepyfile(test_mine=USER_TEST)
    out = pytester.path / "req.json"
    pytester.runpytest("-p", "no:cacheprovider", "--uav-el-run", str(tmp_path / "none"),
                       "--requirements-report", str(out)).assert_outcomes(skipped=1)  # the old option name
    doc = json.loads(out.read_text())
    assert doc["context"]["run_digest"] is None
    assert doc["requirements"]["EL-R12"]["state"] == rq.NOT_VERIFIED


def test_the_plugin_registers_the_campaign_and_slow_markers(pytester):
    pytester.makeini("[pytest]\naddopts = --strict-markers\n")
    pytester.makepyfile(test_m="""
import pytest

@pytest.mark.campaign
@pytest.mark.slow
def test_a():
    pass
""")
    pytester.runpytest("-p", "no:cacheprovider").assert_outcomes(passed=1)
    markers = pytester.runpytest("--markers").stdout.str()
    assert "@pytest.mark.campaign" in markers and "@pytest.mark.slow" in markers
