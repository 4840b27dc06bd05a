"""The requirement registry, the pytest plugin (marker, collection errors, JSON results, JUnit properties),
the three states, and the campaign checks on tiny campaign runs."""

from __future__ import annotations

import copy
import json
import xml.etree.ElementTree as ET

import hypothesis  # noqa: F401  # imported once here: pytester's in-process runs would re-import it every time
import pytest
import yaml

from assurance import requirements as rq
from assurance.perturbations import PAPER_PERTURBATIONS
from assurance.requirements.suite import SUITE_DIR

pytest_plugins = ["pytester"]

CAMPAIGN_TESTS = SUITE_DIR / "test_campaign_requirements.py"

SAMPLE = """
import pytest

pytestmark = pytest.mark.requirements("EL-R05")

@pytest.mark.requirements("EL-R01")
def test_passes():
    pass

@pytest.mark.requirements("EL-R03", "EL-R01")
def test_fails():
    assert 1 == 2, "the default action was not taken"

@pytest.mark.requirements("EL-R04")
def test_skips():
    pytest.skip("insufficient evidence: no run")

@pytest.mark.requirements("EL-R06")
@pytest.mark.xfail(reason="known bug")
def test_expected_failure():
    assert False

class TestGroup:
    pytestmark = pytest.mark.requirements("EL-R07")

    def test_in_class(self):
        pass
"""


def _report(pytester: pytest.Pytester, *args: str) -> tuple[pytest.RunResult, dict]:
    out = pytester.path / "req.json"
    result = pytester.runpytest("-p", "no:cacheprovider", "--requirements-report", str(out), *args)
    return result, json.loads(out.read_text())


# ------------------------------------------------------------------------------------------------
# The registry
# ------------------------------------------------------------------------------------------------
def test_shipped_registry_is_complete_and_consistent():
    from el.flight.pipeline import DEFAULT_TIME_BUDGET_S, PipelineConfig

    reg = rq.load_registry()
    assert reg.ids == tuple(f"EL-R{i:02d}" for i in range(1, 18))
    for req in reg:
        assert req.title and req.text and req.rationale and req.acceptance and req.domain and req.verification_method
        assert set(req.source) <= set(rq.KNOWN_SOURCES)
    p = reg.parameters
    assert p["deployed_monitor"] == PipelineConfig().monitor_name  # EL-R09/R10/R13 judge what ships
    assert p["time_budget_s"] == DEFAULT_TIME_BUDGET_S
    assert tuple(p["required_perturbations"]) == PAPER_PERTURBATIONS
    assert len(reg.sha256) == 64


@pytest.mark.parametrize("edit,message", [
    (lambda d: d["requirements"].append(copy.deepcopy(d["requirements"][0])), "duplicate id 'EL-R01'"),
    (lambda d: d["requirements"][2].pop("acceptance"),
     r"requirements\[2\] \(EL-R03\): missing field\(s\) 'acceptance'"),
    (lambda d: d["requirements"][0].update(source=["ISO26262"]), "unknown source"),
    (lambda d: d["sources"].update(IEEE99="made up"), "not allowed"),
    (lambda d: d["requirements"][1].update(id="R2"), "must look like 'EL-R01'"),
    (lambda d: d["parameters"].pop("deployed_monitor"), "missing 'deployed_monitor'"),
    (lambda d: d.update(format="other/1"), "format must be"),
])
def test_registry_validation_names_file_and_entry(tmp_path, edit, message):
    doc = yaml.safe_load(rq.default_registry_path().read_text())
    edit(doc)
    path = tmp_path / "reg.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(rq.RegistryError, match=message) as exc:
        rq.load_registry(path)
    assert str(path) in str(exc.value)


def test_unreadable_registry(tmp_path):
    with pytest.raises(rq.RegistryError, match="cannot read"):
        rq.load_registry(tmp_path / "missing.yaml")
    (tmp_path / "bad.yaml").write_text("requirements: [")
    with pytest.raises(rq.RegistryError, match="not valid YAML"):
        rq.load_registry(tmp_path / "bad.yaml")


# ------------------------------------------------------------------------------------------------
# The three states
# ------------------------------------------------------------------------------------------------
def T(outcome, message=""):  # noqa: N802
    return rq.TestOutcome(f"t.py::{outcome}", outcome, 0.1, message)


@pytest.mark.parametrize("outcomes,state", [
    ([], rq.NOT_VERIFIED),
    (["passed"], rq.VERIFIED),
    (["passed", "xpassed"], rq.VERIFIED),
    (["passed", "failed"], rq.FAILED),
    (["passed", "error"], rq.FAILED),
    (["xfailed"], rq.FAILED),
    (["passed", "skipped"], rq.NOT_VERIFIED),
    (["passed", "deselected"], rq.NOT_VERIFIED),
    (["skipped", "failed"], rq.FAILED),
    (["not run"], rq.NOT_VERIFIED),
])
def test_requirement_state(outcomes, state):
    assert rq.requirement_state([T(o) for o in outcomes])[0] == state


# ------------------------------------------------------------------------------------------------
# The plugin (pytester)
# ------------------------------------------------------------------------------------------------
def test_marker_is_registered(pytester):
    result = pytester.runpytest("--markers")
    result.stdout.fnmatch_lines(["*@pytest.mark.requirements(*ids)*"])


def test_marker_selects_exactly_the_requirement_tests(pytester):
    pytester.makepyfile(test_sel="""
        import pytest

        @pytest.mark.requirements("EL-R01")
        def test_claims():
            pass

        def test_plain():
            pass

        @pytest.mark.requirements("EL-R02")
        class TestClass:
            def test_method(self):
                pass
    """)
    result = pytester.runpytest("-m", "requirements", "-p", "no:cacheprovider", "-v")
    result.assert_outcomes(passed=2, deselected=1)
    result.stdout.fnmatch_lines(["*test_claims PASSED*", "*test_method PASSED*"])
    assert "test_plain" not in result.stdout.str()
    # -m requirements writes the default report under the rootdir
    doc = json.loads((pytester.path / "reports" / "requirements.json").read_text())
    assert doc["requirements"]["EL-R01"]["state"] == rq.VERIFIED


def test_no_report_without_the_option_or_the_marker_expression(pytester):
    pytester.makepyfile(test_x="""
        import pytest

        @pytest.mark.requirements("EL-R01")
        def test_a():
            pass
    """)
    pytester.runpytest("-p", "no:cacheprovider").assert_outcomes(passed=1)
    pytester.runpytest("-p", "no:cacheprovider", "-m", "not requirements")
    assert not (pytester.path / "reports").exists()


def test_unknown_id_fails_collection(pytester):
    pytester.makepyfile(test_bad="""
        import pytest

        @pytest.mark.requirements("EL-R01", "EL-R99")
        def test_typo():
            pass

        @pytest.mark.requirements()
        def test_empty():
            pass
    """)
    result = pytester.runpytest("-p", "no:cacheprovider")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    err = result.stderr.str()
    assert "test_bad.py::test_typo: unknown requirement id 'EL-R99'" in err
    assert "test_bad.py::test_empty" in err and "names no requirement id" in err
    # even when the test is deselected
    result = pytester.runpytest("-p", "no:cacheprovider", "-k", "nothing")
    assert result.ret == pytest.ExitCode.USAGE_ERROR


def test_bad_registry_option_is_a_usage_error(pytester, tmp_path):
    (tmp_path / "reg.yaml").write_text("format: nope\n")
    pytester.makepyfile(test_x="def test_a():\n    pass\n")
    result = pytester.runpytest("--requirements-registry", str(tmp_path / "reg.yaml"))
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "requirement registry" in result.stderr.str() and "format must be" in result.stderr.str()


def test_json_results_per_requirement(pytester):
    pytester.makepyfile(test_sample=SAMPLE)
    result, doc = _report(pytester)
    result.assert_outcomes(passed=2, failed=1, skipped=1, xfailed=1)
    reqs = doc["requirements"]
    assert doc["format"] == rq.RESULTS_FORMAT and set(reqs) == set(rq.load_registry().ids)
    state = {rid: r["state"] for rid, r in reqs.items()}
    assert state["EL-R01"] == rq.FAILED  # one passing and one failing claim
    assert state["EL-R03"] == rq.FAILED
    assert state["EL-R04"] == rq.NOT_VERIFIED  # skipped
    assert state["EL-R06"] == rq.FAILED  # an expected failure is a known failure of the requirement
    assert state["EL-R07"] == rq.VERIFIED  # class-level marker
    assert state["EL-R05"] == rq.FAILED  # module-level marker: every test of the module claims it
    assert state["EL-R02"] == rq.NOT_VERIFIED and reqs["EL-R02"]["reason"] == "no test claims it"
    tests = {t["nodeid"]: t for t in reqs["EL-R01"]["tests"]}
    assert set(tests) == {"test_sample.py::test_passes", "test_sample.py::test_fails"}
    fail = tests["test_sample.py::test_fails"]
    assert fail["outcome"] == "failed" and "the default action was not taken" in fail["message"]
    assert fail["duration"] >= 0
    skip = reqs["EL-R04"]["tests"][0]
    assert skip["outcome"] == "skipped" and skip["message"] == "insufficient evidence: no run"
    assert doc["summary"] == {rq.VERIFIED: 1, rq.FAILED: 4, rq.NOT_VERIFIED: 12}
    result.stdout.fnmatch_lines(["*safety requirements*", "*failed:  4*EL-R01*", "*requirement results written to*"])


def test_errors_in_setup_fail_the_requirement_and_deselected_tests_leave_it_open(pytester):
    pytester.makepyfile(test_fx="""
        import pytest

        @pytest.fixture
        def broken():
            raise RuntimeError("fixture exploded")

        @pytest.mark.requirements("EL-R01")
        def test_setup_error(broken):
            pass

        @pytest.mark.requirements("EL-R02")
        def test_selected():
            pass

        @pytest.mark.requirements("EL-R02")
        def test_other():
            pass
    """)
    _, doc = _report(pytester, "-k", "not test_other")
    r1, r2 = doc["requirements"]["EL-R01"], doc["requirements"]["EL-R02"]
    assert r1["state"] == rq.FAILED and r1["tests"][0]["outcome"] == "error"
    assert "fixture exploded" in r1["tests"][0]["message"]
    assert r2["state"] == rq.NOT_VERIFIED
    assert {t["outcome"] for t in r2["tests"]} == {"passed", "deselected"}


def test_junit_xml_carries_the_requirements(pytester):
    pytester.makepyfile(test_j="""
        import pytest

        @pytest.mark.requirements("EL-R03", "EL-R04")
        def test_two():
            pass

        def test_none():
            pass
    """)
    xml = pytester.path / "junit.xml"
    pytester.runpytest("-p", "no:cacheprovider", f"--junitxml={xml}").assert_outcomes(passed=2)
    cases = {c.get("name"): c for c in ET.parse(xml).getroot().iter("testcase")}
    props = [(p.get("name"), p.get("value")) for p in cases["test_two"].iter("property")]
    assert props == [("requirements", "EL-R03,EL-R04")]  # one comma-joined property: what test tools import
    assert not list(cases["test_none"].iter("property"))


# ------------------------------------------------------------------------------------------------
# The requirement targets: --uav-el-targets, $UAV_EL_TARGETS, set_targets
# ------------------------------------------------------------------------------------------------
TARGET_TEST = """
import pytest
from assurance.requirements.pytest_plugin import registry

@pytest.mark.requirements("EL-R10")
def test_reads_the_targets(request):
    reg = registry(request.config)
    assert "shown with 99% confidence" in reg["EL-R10"].text
"""


def test_targets_option_reaches_the_checks_and_the_results(pytester, tmp_path):
    (tmp_path / "t.json").write_text(json.dumps({"confidence": 0.99, "unsafe_landing_bound": 0.01}))
    pytester.makepyfile(test_t=TARGET_TEST)
    result, doc = _report(pytester, "--uav-el-targets", str(tmp_path / "t.json"))
    result.assert_outcomes(passed=1)
    reg = doc["registry"]
    assert reg["targets"] == {"confidence": 0.99, "unsafe_landing_bound": 0.01}
    assert reg["targets_source"] == str((tmp_path / "t.json").resolve())
    want = rq.load_registry(targets={"confidence": 0.99, "unsafe_landing_bound": 0.01})
    assert reg["parameters_sha256"] == want.parameters_sha256 and reg["parameters"]["confidence"] == 0.99


def test_targets_from_the_environment_and_from_set_targets(pytester, tmp_path, monkeypatch):
    (tmp_path / "env.json").write_text(json.dumps({"confidence": 0.99}))
    monkeypatch.setenv("UAV_EL_TARGETS", str(tmp_path / "env.json"))
    pytester.makepyfile(test_t=TARGET_TEST)
    result, doc = _report(pytester)
    result.assert_outcomes(passed=1)
    assert doc["registry"]["targets"] == {"confidence": 0.99}
    # a plugin or conftest binding targets in code (e.g. a system file's [targets]) replaces the file
    pytester.makeconftest("""
        from assurance.requirements.pytest_plugin import set_targets

        def pytest_configure(config):
            set_targets(config, {"confidence": 0.99, "radius_m": 2.5}, source="uav-el.toml [targets]")
    """)
    result, doc = _report(pytester)
    result.assert_outcomes(passed=1)
    assert doc["registry"]["targets"] == {"confidence": 0.99, "radius_m": 2.5}
    assert doc["registry"]["targets_source"] == "uav-el.toml [targets]"


@pytest.mark.parametrize("content,message", [
    ('{"radius": 2.5}', "unknown target 'radius'; known: deployed_monitor"),
    ('{"confidence": 1.5}', r"confidence = 1.5: must be a number in \[0.5, 1\)"),
    ("[0.99]", "must hold a JSON object"),
])
def test_a_bad_targets_file_is_a_usage_error(pytester, tmp_path, content, message):
    (tmp_path / "t.json").write_text(content)
    pytester.makepyfile(test_x="def test_a():\n    pass\n")
    result = pytester.runpytest("-p", "no:cacheprovider", "--uav-el-targets", str(tmp_path / "t.json"))
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    err = result.stderr.str()
    assert "requirement registry" in err and "t.json" in err
    result.stderr.re_match_lines([f".*{message}.*"])


# ------------------------------------------------------------------------------------------------
# The campaign requirement tests on tiny runs (the packaged suite, run by pytester)
# ------------------------------------------------------------------------------------------------
def _campaign_report(pytester, run, *args):
    out = pytester.path / "campaign.json"
    result = pytester.runpytest(str(CAMPAIGN_TESTS), "-p", "no:cacheprovider", "--uav-el-run", str(run),
                                "--requirements-report", str(out), *args)
    return result, json.loads(out.read_text())


@pytest.fixture(scope="module")
def lhd_registry(tmp_path_factory):
    """The shipped registry with LHD as the deployed monitor: the tiny campaigns evaluate the paper's monitors."""
    import yaml

    doc = yaml.safe_load(rq.default_registry_path().read_text(encoding="utf-8"))
    doc["parameters"].update(deployed_monitor="lhd", calibration_card=None)
    path = tmp_path_factory.mktemp("registry") / "requirements.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return str(path)


def test_campaign_tests_verify_coverage_and_gain_on_a_complete_run(pytester, tiny_campaign, lhd_registry):
    result, doc = _campaign_report(pytester, tiny_campaign["run"], "-k", "coverage or safety_gain",
                                   "--requirements-registry", lhd_registry)
    result.assert_outcomes(passed=3)
    state = {rid: r["state"] for rid, r in doc["requirements"].items()}
    assert state["EL-R04"] == state["EL-R08"] == state["EL-R09"] == rq.VERIFIED
    assert doc["context"]["run"] == str(tiny_campaign["run"].resolve())


def test_a_missing_perturbation_leaves_r08_r09_not_verified_not_failed(pytester, tiny_run_without, lhd_registry):
    run = tiny_run_without("pixel_trap")
    result, doc = _campaign_report(pytester, run, "-k", "perturbation_coverage or safety_gain",
                                   "--requirements-registry", lhd_registry)
    result.assert_outcomes(skipped=2)
    for rid in ("EL-R08", "EL-R09"):
        entry = doc["requirements"][rid]
        assert entry["state"] == rq.NOT_VERIFIED, entry
        assert "insufficient evidence" in entry["tests"][0]["message"] and "pixel_trap" in entry["tests"][0]["message"]


def test_campaign_checks_judge_the_targets_given_on_the_command_line(pytester, tiny_campaign, tmp_path):
    """End to end on the tiny run: the deployed monitor, EL-R10's confidence and R come from --uav-el-targets
    (no registry copy): 10 images cannot show 0.05 at 99%, and a run planned with R = 2 m does not judge R = 2.5 m."""
    targets = {"deployed_monitor": "lhd", "calibration_card": None, "unsafe_landing_bound": 0.05,
               "confidence": 0.99, "radius_m": 2.5}
    (tmp_path / "t.json").write_text(json.dumps(targets))
    result, doc = _campaign_report(pytester, tiny_campaign["run"], "-k", "unsafe_landing_bound or pose_error_margin "
                                   "or safety_gain", "--uav-el-targets", str(tmp_path / "t.json"))
    result.assert_outcomes(passed=1, skipped=2)
    reqs = doc["requirements"]
    assert reqs["EL-R09"]["state"] == rq.VERIFIED  # the deployed monitor is the targets' "lhd"
    r10, r14 = reqs["EL-R10"]["tests"][0]["message"], reqs["EL-R14"]["tests"][0]["message"]
    assert reqs["EL-R10"]["state"] == rq.NOT_VERIFIED and "at 99% confidence (needs >= 90 images" in r10
    assert reqs["EL-R14"]["state"] == rq.NOT_VERIFIED and "declare R = 2.5 m, beta = 1.7" in r14
    assert doc["registry"]["targets"] == targets


def test_without_a_run_the_campaign_requirements_are_not_verified(pytester, tmp_path):
    result, doc = _campaign_report(pytester, tmp_path / "no-such-run")
    assert result.ret == pytest.ExitCode.OK
    for rid in ("EL-R04", "EL-R08", "EL-R09", "EL-R10", "EL-R11", "EL-R12", "EL-R13"):
        assert doc["requirements"][rid]["state"] == rq.NOT_VERIFIED
        assert "no campaign run" in doc["requirements"][rid]["tests"][0]["message"]


# ------------------------------------------------------------------------------------------------
# The campaign checks themselves
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny_tables(tiny_campaign):
    from assurance.analysis.table import results_table
    from assurance.campaign import readouts

    run = tiny_campaign["run"]
    return (readouts.load_table(run, "images"), readouts.load_table(run, "candidates"),
            results_table(run, n_boot=200))


def test_monitor_coverage_catches_a_pipeline_that_ignores_the_monitor(monitor_runs):
    from assurance.campaign import readouts

    good = rq.check_monitor_coverage(*(readouts.load_table(monitor_runs["good"], t) for t in readouts.TABLES))
    bad = rq.check_monitor_coverage(*(readouts.load_table(monitor_runs["broken"], t) for t in readouts.TABLES))
    assert good.status == rq.PASS, good.message()
    assert bad.status == rq.FAIL and bad.rows
    assert all("which the monitor rejected" in r["problem"] for r in bad.rows)


def test_perturbation_coverage_counts_images(tiny_tables):
    images, _, _ = tiny_tables
    assert rq.check_perturbation_coverage(images, PAPER_PERTURBATIONS, 10).status == rq.PASS
    short = rq.check_perturbation_coverage(images, PAPER_PERTURBATIONS, 11)
    assert short.status == rq.INSUFFICIENT and "10 evaluated images, fewer than the 11 needed" in short.summary
    faulted = images.copy()
    faulted.loc[faulted["perturbation"] == "fog", "fault"] = "ValueError: unreadable"
    assert rq.check_perturbation_coverage(faulted, PAPER_PERTURBATIONS, 10).status == rq.INSUFFICIENT


def test_safety_gain_and_unsafe_landing_bound(tiny_tables):
    _, _, table = tiny_tables
    gain = rq.check_safety_gain(table, "lhd", PAPER_PERTURBATIONS, 10)
    assert gain.status == rq.PASS, gain.message()
    worse = table.copy()
    worse.loc[worse["perturbation"] == "fog", "g_star_lo95"] = -0.1
    failed = rq.check_safety_gain(worse, "lhd", PAPER_PERTURBATIONS, 10)
    assert failed.status == rq.FAIL and "fog" in failed.summary
    assert rq.check_safety_gain(table, "lhd+mcd:n=10,rho=0.5", PAPER_PERTURBATIONS, 10).status == rq.INSUFFICIENT

    # 10 images cannot show 5% even with no unsafe landing: not verified, never failed
    small = rq.check_unsafe_landing_bound(table, "lhd", 0.05, PAPER_PERTURBATIONS)
    assert small.status == rq.INSUFFICIENT and "needs >= 59 images" in small.summary
    from assurance.analysis.metrics import clopper_pearson_upper

    for bound in (0.05, 0.0419, 0.01, 0.2):
        n = rq.images_needed(bound)
        assert clopper_pearson_upper(0, n) <= bound < clopper_pearson_upper(0, n - 1)
    # a bound the sample can show: the scenarios with unsafe landings decide
    unsafe = table[(table["monitor"] == "lhd") & (table["unsafe_landing_rate"] > 0)]
    loose = rq.check_unsafe_landing_bound(table, "lhd", 0.5, PAPER_PERTURBATIONS)
    if unsafe["unsafe_landing_ub95"].max() > 0.5:
        assert loose.status == rq.FAIL
    else:
        assert loose.status == rq.PASS


def test_decision_time_and_determinism_checks(tiny_campaign, tiny_tables):
    images, _, table = tiny_tables
    assert rq.check_decision_time(images, "lhd", 10.0).status == rq.PASS
    assert rq.check_decision_time(images, "lhd", 1e-9).status == rq.FAIL
    assert rq.check_table_recomputation(tiny_campaign["run"], n_boot=200).status == rq.PASS


def test_rerun_of_a_shard_reproduces_the_readouts(tiny_campaign, tmp_path):
    from helpers import OracleSegmenter

    ev = rq.check_rerun(tiny_campaign["run"], work_dir=tmp_path, segmenter=OracleSegmenter(128))
    assert ev.status == rq.PASS, ev.message()
    assert ev.rows[0]["shard"].startswith(("fog", "motion_blur", "pixel_trap", "shifted_pixels"))
    # the manifest's weights are not the segmenter the run used: the re-run sees different readouts
    other = rq.check_rerun(tiny_campaign["run"], work_dir=tmp_path / "w")
    assert other.status == rq.FAIL


def test_a_rerun_is_bounded_in_threads_and_time(tiny_campaign, tmp_path, monkeypatch):
    """The manifest is the applicant's: a thread count it records is not obeyed beyond a bound, and a re-run that
    does not end (a network looping without end) is stopped and reported, never a hang of the auditor's verify."""
    import shutil
    import time

    from helpers import OracleSegmenter, sleep_a_minute

    from assurance.requirements import determinism

    run = tmp_path / "run"
    shutil.copytree(tiny_campaign["run"], run)
    man = json.loads((run / "manifest.json").read_text())
    (run / "manifest.json").write_text(json.dumps({**man, "threads_per_worker": 3000}))
    ev = rq.check_rerun(run, work_dir=tmp_path / "a", segmenter=OracleSegmenter(128))
    assert ev.status == rq.INSUFFICIENT and "3000 threads per worker" in ev.message(), ev.message()

    monkeypatch.setattr(determinism, "RERUN_SECONDS", 1.0)
    monkeypatch.setattr(determinism, "execute", sleep_a_minute)
    t = time.monotonic()
    ev = rq.check_rerun(tiny_campaign["run"], work_dir=tmp_path / "b", segmenter=OracleSegmenter(128))
    assert time.monotonic() - t < 30
    assert ev.status == rq.INSUFFICIENT and "did not finish within 1 s" in ev.message(), ev.message()


@pytest.mark.parametrize("edit,message", [
    (lambda d: d["requirements"][3].update(owner="me"), r"requirements\[3\] \(EL-R04\): unknown field\(s\) 'owner'"),
    (lambda d: d["requirements"][0]["verification"].update(kind="test"), r"field 'verification.kind'"),
    (lambda d: d["requirements"][0].update(title="  "), r"requirements\[0\] \(EL-R01\): field 'title'"),
    (lambda d: d.pop("operating_domain"), r"missing field\(s\) 'operating_domain'"),
])
def test_the_registry_structure_is_checked_by_its_json_schema(tmp_path, edit, message):
    doc = yaml.safe_load(rq.default_registry_path().read_text())
    edit(doc)
    path = tmp_path / "reg.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(rq.RegistryError, match=message):
        rq.load_registry(path)
