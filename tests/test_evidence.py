"""The evidence report and its gate: files, identity by SHA-256 (EL-R12), escaping, states, baseline, PDF."""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
from pathlib import Path

import hypothesis  # noqa: F401  # imported once here: pytester's in-process runs would re-import it every time
import pandas as pd
import pytest
from helpers import reseal_shard

from assurance import cli
from assurance import requirements as rq
from assurance.campaign import readouts
from assurance.evidence import generate
from assurance.requirements.suite import SUITE_DIR

pytest_plugins = ["pytester"]

CAMPAIGN_TESTS = SUITE_DIR / "test_campaign_requirements.py"
SCRIPT = "<script>alert('x')</script>"
WEIRD_WEIGHTS = '/models/w<b>"&\'.pt'


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def weasyprint_ok() -> bool:
    try:
        import weasyprint  # noqa: F401
    except Exception:
        return False
    return True


def pytest_results(pytester, run, out, *args) -> Path:
    """Run the real campaign requirement tests on ``run`` and return the results JSON."""
    path = out / "requirements.json"
    pytester.runpytest(str(CAMPAIGN_TESTS), "-p", "no:cacheprovider", "--uav-el-run", str(run),
                       "--requirements-report", str(path), *args)
    sign_as_verify(run, out)
    return path


def sign_as_verify(run, out, waivers=None) -> None:
    """Sign a session's results as ``uav-el verify [--waivers W]`` does (the session's key; by default the shipped
    waivers, which the evidence step applies to the shipped system)."""
    from assurance.attest.keys import load_signing_key
    from assurance.requirements.attestation import sign_session_results
    from assurance.system.build import shipped_waivers

    if (out / "requirements.json").is_file():
        sign_session_results(run, out, load_signing_key(), waivers=waivers or shipped_waivers())


@pytest.fixture(scope="module")
def hostile_run(tiny_campaign, tmp_path_factory):
    """A copy of the tiny run in a folder named with HTML specials, a monitor reason holding a script tag
    and a weights path full of specials in its manifest."""
    run = tmp_path_factory.mktemp("hostile") / 'run<&>"x'
    shutil.copytree(tiny_campaign["run"], run)
    for shard in (run / "shards").iterdir():
        if shard.name.startswith("none-s"):
            path = shard / "candidates.parquet"
            cands = pd.read_parquet(path)
            cands["reason"] = SCRIPT
            cands.to_parquet(path, index=False)
            reseal_shard(run, shard.name)
    man = json.loads((run / "manifest.json").read_text())
    man["weights"]["path"] = WEIRD_WEIGHTS
    (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True))
    return run


@pytest.fixture(scope="module")
def report(hostile_run, tiny_run_without, tmp_path_factory):
    """The full report (PDF included) of the hostile run, with a baseline that lacks pixel_trap."""
    out = tmp_path_factory.mktemp("report") / "reports"
    baseline = tiny_run_without("pixel_trap")
    rep = generate(hostile_run, out, baseline=baseline, n_boot=200)
    return rep, json.loads(rep.json.read_text()), rep.html.read_text(encoding="utf-8")


@pytest.mark.requirements("EL-R12")
def test_report_identifies_every_artefact_by_sha256(report, hostile_run):
    rep, doc, html = report
    ident = doc["identity"]
    man = readouts.read_manifest(hostile_run)
    assert ident["weights_sha256"] == man["weights"]["sha256"] and len(ident["weights_sha256"]) == 64
    assert ident["data_sha256"] == man["data"]["sha256"] and len(ident["data_sha256"]) == 64
    assert ident["config_sha256"] == rq.config_sha256(man["config"])
    assert ident["registry_sha256"] == sha(rq.default_registry_path())
    assert ident["results_csv_sha256"] == sha(rep.out / "results.csv")
    assert ident["manifest_sha256"] == sha(hostile_run / "manifest.json")
    assert len(ident["code_sha256"]) == 64 and len(ident["templates_sha256"]) == 64
    for key in ("weights_sha256", "data_sha256", "config_sha256", "registry_sha256", "code_sha256"):
        assert ident[key] in html, key
    sums = dict(line.split("  ")[::-1] for line in (rep.out / "SHA256SUMS").read_text().splitlines())
    for name, digest in sums.items():
        assert sha(rep.out / name) == digest
    assert {"evidence.html", "evidence.json", "results.csv"} <= set(sums)


def test_report_files_html_json_pdf(report):
    rep, doc, html = report
    assert rep.html.is_file() and rep.json.is_file() and html.startswith("<!DOCTYPE html>")
    assert "<style>" in html and "<link" not in html  # self-contained: CSS inline ...
    assert 'src="data:image/png;base64,' in html and 'src="data:image/jpeg;base64,' in html  # ... images embedded
    assert "http://" not in html and "https://" not in html
    if not weasyprint_ok():
        pytest.skip("WeasyPrint cannot be imported here: the PDF is not checked")
    assert rep.pdf is not None and rep.pdf.read_bytes()[:4] == b"%PDF" and rep.pdf_error is None


def test_html_escapes_everything_user_controlled(report):
    _, doc, html = report
    from assurance.evidence.linking import SCRIPT as OWN

    assert SCRIPT not in html and html.count("<script") == 1 and f"<script>{OWN}</script>" in html  # its own only
    assert "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt;" in html  # the monitor reason, escaped
    assert 'run&lt;&amp;&gt;&#34;x' in html and 'run<&>"x' not in html  # the run folder name
    assert "w&lt;b&gt;&#34;&amp;&#39;.pt" in html and WEIRD_WEIGHTS not in html  # a configuration value
    assert doc["identity"]["weights_path"] == WEIRD_WEIGHTS  # JSON keeps the raw value


def test_report_contents(report):
    rep, doc, html = report
    for section in ("What was assessed", "Operating domain and assumptions", "Traceability", "Results table",
                    "What the sample size can and cannot show", "Plots", "Perturbations", "Every unsafe landing",
                    "What changed since the baseline", "Limitations", "Requirements (full text)", "Reproduce"):
        assert section in html, section
    assert "0 unsafe landings in 10 images the rate can still be as high as 25.9%" in html
    assert "Required beta" in html and "1.56" in html
    # every requirement of the registry in the matrix, with a state
    for rid in rq.load_registry().ids:
        assert f"<strong>{rid}</strong>" in html
    assert set(doc["requirements"]) == set(rq.load_registry().ids)
    # no requirement results given: every requirement is open, and the report says why
    assert doc["gate"]["counts"] == {rq.VERIFIED: 0, rq.FAILED: 0, rq.NOT_VERIFIED: 17}
    assert any("no requirement test results" in w for w in doc["warnings"])
    # the results table of the JSON is the run's table
    assert len(doc["results"]) == 12 and {r["perturbation"] for r in doc["results"]} >= {"fog", "pixel_trap"}
    # the baseline lacks pixel_trap: its rows are new, and the identity is unchanged
    base = doc["baseline"]
    assert {r["status"] for r in base["rows"] if r["scenario"].startswith("pixel_trap")} == {"new"}
    changed = {r["item"]: r["changed"] for r in base["identity"]}
    assert changed["Weights SHA-256"] == changed["Data SHA-256"] == "same"
    assert changed["Configuration SHA-256"] == "changed"  # one perturbation fewer
    # the gallery: one picture per perturbation
    assert html.count("severity 3</figcaption>") == 5 and "none (unperturbed)</figcaption>" in html


def test_every_unsafe_landing_is_drawn(report, hostile_run):
    _, doc, html = report
    images = readouts.load_table(hostile_run, "images")
    unsafe = images[images["decision_unsafe"].astype(bool)]
    assert doc["unsafe_landings"]["every_configuration"] == len(unsafe) > 0  # fog fools the oracle
    deployed = doc["unsafe_landings"]["deployed_configuration"]
    assert doc["unsafe_landings"]["deployed"] == (None if deployed not in set(images["monitor"]) else
                                                  int(unsafe["monitor"].eq(deployed).sum()))
    groups = {(r.perturbation, r.key, r.selected) for r in unsafe.itertuples()}
    assert html.count('class="example unsafe compact"') == len(groups)


# ------------------------------------------------------------------------------------------------
# The gate
# ------------------------------------------------------------------------------------------------
@pytest.fixture
def evidence_cli(monkeypatch):
    """``uav-el evidence`` in-process (registered here in case the command table does not list it yet)."""
    monkeypatch.setitem(cli.COMMANDS, "evidence", "evidence")
    return lambda *args: cli.main(["evidence", *map(str, args)])


def test_gate_turns_red_for_exactly_the_broken_requirement(pytester, monitor_runs, evidence_cli, tmp_path, capsys):
    """A pipeline variant that ignores the monitor (lands on rank 0 regardless) fails EL-R04, and only EL-R04."""
    bad_json = pytest_results(pytester, monitor_runs["broken"], tmp_path / "bad", "-k", "monitor_coverage")
    bad = json.loads(bad_json.read_text())
    assert bad["requirements"]["EL-R04"]["state"] == rq.FAILED
    assert "which the monitor rejected" in bad["requirements"]["EL-R04"]["tests"][0]["message"]
    capsys.readouterr()
    code = evidence_cli("--run", monitor_runs["broken"], "--out", tmp_path / "bad", "--no-pdf", "--boot", 100)
    out = capsys.readouterr().out
    assert code == 1
    assert "failed:         1  EL-R04" in out and "gate: FAILED" in out
    doc = json.loads((tmp_path / "bad" / "evidence.json").read_text())
    assert doc["gate"]["failed"] == ["EL-R04"] and doc["gate"]["exit_code"] == 1

    good_json = pytest_results(pytester, monitor_runs["good"], tmp_path / "good", "-k", "monitor_coverage")
    assert json.loads(good_json.read_text())["requirements"]["EL-R04"]["state"] == rq.VERIFIED
    capsys.readouterr()
    # the tests deselected with -k decide nothing: their requirements are not verified, and that fails the gate
    assert evidence_cli("--run", monitor_runs["good"], "--out", tmp_path / "good", "--no-pdf", "--boot", 100) == 1
    out = capsys.readouterr().out
    assert "failed:         0" in out and "not verified:  16  EL-R01, EL-R02" in out
    assert "gate: FAILED (not verified: EL-R01, EL-R02, EL-R03, EL-R05" in out
    assert f"report: {tmp_path / 'good' / 'evidence.html'}" in out


def test_waiver_accepts_a_listed_failure_but_not_under_strict(pytester, monitor_runs, evidence_cli, tmp_path, capsys,
                                                             monkeypatch):
    """A failed requirement listed in a waivers file stays "failed" in the report but does not fail the gate;
    --strict (a certification release) ignores waivers; an unlisted failure still fails."""
    from helpers import allow_weaker_registry, lenient_registry

    lenient = lenient_registry(tmp_path)  # the requirements deselected here do not block: the waiver is tested
    allow_weaker_registry(monkeypatch)
    pytest_results(pytester, monitor_runs["broken"], tmp_path / "bad", "-k", "monitor_coverage",
                   "--uav-el-registry", str(lenient))
    import datetime as dt

    soon = (dt.datetime.now(dt.UTC).date() + dt.timedelta(days=100)).isoformat()  # within the declared maximum
    waivers = tmp_path / "waivers.yaml"
    waivers.write_text("waivers:\n  - id: EL-R04\n    reason: known <bad> variant\n    tracked_by: monitor work\n"
                       f"    owner: monitor maintainers\n    expires: {soon}\n")
    args = ("--run", monitor_runs["broken"], "--out", tmp_path / "bad", "--no-pdf", "--boot", 100,
            "--registry", lenient)
    capsys.readouterr()
    assert evidence_cli(*args, "--waivers", waivers) == 1  # the results were signed with other waivers pinned
    assert "signed with waivers_sha256" in capsys.readouterr().out
    real_evidence_cli = evidence_cli

    def evidence_cli(*a):  # noqa: F811  (as uav-el verify --waivers W would have signed the results)
        sign_as_verify(monitor_runs["broken"], tmp_path / "bad", a[a.index("--waivers") + 1])
        return real_evidence_cli(*a)

    assert evidence_cli(*args, "--waivers", waivers) == 0
    assert "failed but waived: EL-R04" in capsys.readouterr().out
    doc = json.loads((tmp_path / "bad" / "evidence.json").read_text())
    assert doc["gate"]["failed"] == ["EL-R04"] and "EL-R04" in doc["gate"]["waived"]
    html = (tmp_path / "bad" / "evidence.html").read_text()
    assert "known &lt;bad&gt; variant" in html and "owner monitor maintainers" in html
    cover = html.split("<nav>")[0]  # page 1: the waived failure is still a failure
    assert 'href="#req-EL-R04">EL-R04</a> (failed, waived)' in cover and "Gate: WAIVED" in cover  # id linked
    assert evidence_cli(*args, "--waivers", waivers, "--strict") == 1
    other = tmp_path / "other.yaml"
    other.write_text("waivers:\n  - id: EL-R09\n    reason: r\n    tracked_by: t\n    owner: o\n    expires: 99.0.0\n")
    assert evidence_cli(*args, "--waivers", other) == 1
    # an expired waiver (by date or by version) waives nothing and fails the gate by itself
    for expires in ("2001-01-01", "0.0.1"):
        old = tmp_path / "old.yaml"
        old.write_text(waivers.read_text().replace(soon, expires))
        capsys.readouterr()
        assert evidence_cli(*args, "--waivers", old) == 1
        out = capsys.readouterr().out
        assert f"the waiver of EL-R04 (owner: monitor maintainers) expired ({expires})" in out
    for text, why in (("waivers:\n  - id: EL-R04\n", "needs an id, a reason, tracked_by, an owner and expires"),
                      (waivers.read_text().replace(soon, "soon"), "expires must be a date")):
        bad = tmp_path / "bad.yaml"
        bad.write_text(text)
        assert evidence_cli(*args, "--waivers", bad) == 2
        assert why in capsys.readouterr().err


def test_missing_weasyprint_keeps_the_html_and_says_what_to_install(monitor_runs, tmp_path, monkeypatch, capsys,
                                                                    evidence_cli):
    from helpers import allow_weaker_registry

    allow_weaker_registry(monkeypatch)
    monkeypatch.setitem(sys.modules, "weasyprint", None)  # import weasyprint -> ImportError
    out = tmp_path / "r"
    (out).mkdir()
    (out / "evidence.pdf").write_bytes(b"%PDF old report")
    from helpers import lenient_registry

    lenient = lenient_registry(tmp_path)  # nothing verified blocks on this small run: the PDF alone is tested
    rep = generate(monitor_runs["good"], out, n_boot=100, registry=lenient)
    assert rep.html.is_file() and rep.pdf is None and not (out / "evidence.pdf").exists()
    assert "pip install 'uav-el-assurance[pdf]'" in rep.pdf_error and "libpango" in rep.pdf_error  # a wheel's
    assert rep.exit_code == 0  # the PDF counts only with --strict
    assert generate(monitor_runs["good"], out, n_boot=100, strict=True, registry=lenient).exit_code == 1
    assert rep.pdf_error in rep.warnings and not any("uav-el-assurance[pdf]" in s for s in rep.summary_lines())
    assert evidence_cli("--run", monitor_runs["good"], "--out", out, "--boot", 50, "--registry", lenient) == 0
    said = capsys.readouterr()
    assert "uav-el-assurance[pdf]" in said.err and "uav-el-assurance[pdf]" not in said.out  # on stderr


def test_results_of_another_run_fail_the_gate(pytester, monitor_runs, tmp_path):
    results = pytest_results(pytester, monitor_runs["good"], tmp_path, "-k", "monitor_coverage")
    rep = generate(monitor_runs["broken"], tmp_path / "r", requirements=results, pdf=False, n_boot=100)
    assert any("produced on run" in w for w in rep.warnings)
    assert rep.exit_code == 1 and "EL-R04" not in rep.ids(rq.FAILED)  # failed by the binding, not by a state
    assert any("produced on other readouts (run digest" in p for p in rep.problems)
    # and the campaign check on this run contradicts the verified state
    assert any(p.startswith("EL-R04: the test results say verified, this report's own check of the run says fail")
               for p in rep.problems)
    assert generate(monitor_runs["broken"], tmp_path / "r", requirements=results, pdf=False, n_boot=100,
                    strict=True).exit_code == 1


def _forge(doc: dict, state: str = rq.VERIFIED) -> dict:
    doc = json.loads(json.dumps(doc))
    for entry in doc["requirements"].values():
        entry["state"] = state
    return doc


def test_hostile_1_forged_requirement_states_never_pass_the_gate(pytester, monitor_runs, evidence_cli, tmp_path,
                                                                  capsys):
    """Hostile case 1: states set to "verified" by hand, with --strict, exit 1 (they passed before)."""
    results = pytest_results(pytester, monitor_runs["broken"], tmp_path, "-k", "monitor_coverage")
    doc = json.loads(results.read_text())
    assert doc["context"]["run_digest"] and doc["context"]["code_sha256"]
    forged = tmp_path / "forged.json"
    args = ("--run", monitor_runs["broken"], "--out", tmp_path / "r", "--no-pdf", "--boot", 100,
            "--requirements", forged)
    # every state "verified": each contradicts its own test outcomes (or has none), EL-R04 the run's check too
    forged.write_text(json.dumps(_forge(doc)))
    capsys.readouterr()
    assert evidence_cli(*args, "--strict") == 1
    out = capsys.readouterr().out
    assert "gate: FAILED" in out and "is 'verified' but its own test outcomes give 'failed'" in out
    assert "EL-R01 is 'verified' with no test outcome behind it" in out
    # consistent forgery (tests rewritten as passed): the run's own check still refutes EL-R04
    consistent = _forge(doc)
    for entry in consistent["requirements"].values():
        for t in entry["tests"]:
            t["outcome"] = "passed"
    consistent["requirements"] = {"EL-R04": consistent["requirements"]["EL-R04"]}
    forged.write_text(json.dumps(consistent))
    assert evidence_cli(*args, "--strict") == 1
    assert "EL-R04: the test results say verified, this report's own check of the run says fail" in \
        capsys.readouterr().out
    # results not bound (digest, code, registry removed or altered)
    for key, value in (("run_digest", None), ("run_digest", "0" * 64), ("code_sha256", "f" * 64)):
        unbound = json.loads(results.read_text())
        unbound["context"][key] = value
        forged.write_text(json.dumps(unbound))
        assert evidence_cli(*args) == 1
        assert "not bound to a run" in (out := capsys.readouterr().out) or "produced on other" in out


def test_hostile_2_altered_shard_is_named_and_gets_no_report(tiny_campaign, tmp_path, evidence_cli, capsys):
    """Hostile case 2: true_unsafe flipped in one shard: evidence and table exit 4 naming the shard and
    file; a re-run of the campaign re-computes that shard and says so."""
    from conftest import TINY_WW
    from helpers import OracleSegmenter

    from assurance.campaign.run import Execution, describe, run_campaign

    run = tmp_path / "run"
    shutil.copytree(tiny_campaign["run"], run)
    shard = next(p for p in sorted((run / "shards").iterdir())
                 if p.name.startswith("none-s") and pd.read_parquet(p / "candidates.parquet")["selected"].any())
    path = shard / "candidates.parquet"
    cands = pd.read_parquet(path)
    before = cands["true_unsafe"].copy()
    cands.loc[cands["selected"], "true_unsafe"] = ~cands.loc[cands["selected"], "true_unsafe"]
    cands.to_parquet(path, index=False)
    capsys.readouterr()
    assert evidence_cli("--run", run, "--out", tmp_path / "r", "--no-pdf", "--boot", 50) == 4
    err = capsys.readouterr().err
    assert f"shard {shard.name}: candidates.parquet differs from its SHA256SUMS" in err
    assert not (tmp_path / "r" / "evidence.html").exists()
    assert cli.main(["table", str(run), "--boot", "50"]) == 4
    assert shard.name in capsys.readouterr().err
    summary = run_campaign(tiny_campaign["data"], run, tiny_campaign["config"],
                           segmenter=OracleSegmenter(TINY_WW), execution=Execution(progress=False))
    assert summary["done"] == 1 and summary["repaired"] == [
        f"{shard.name}: candidates.parquet differs from its SHA256SUMS (altered or truncated)"]
    assert "1 damaged shard(s) failed verification and were run again" in describe(summary)
    assert pd.read_parquet(path)["true_unsafe"].equals(before) and (run / "damaged" / f"{shard.name}.0").is_dir()
    assert cli.main(["table", str(run), "--boot", "50"]) == 0


def test_cli_errors(evidence_cli, tmp_path, capsys):
    assert evidence_cli("--run", tmp_path / "nothing", "--out", tmp_path / "o") == 2
    assert "not a campaign run" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------
# Formats auditors' tools read
# ------------------------------------------------------------------------------------------------
def _schema(name: str) -> dict:
    from importlib import resources

    return json.loads(resources.files("assurance").joinpath(f"data/{name}.schema.json").read_text())


def test_evidence_and_requirement_results_follow_their_json_schemas(report, pytester, monitor_runs, tmp_path):
    import jsonschema

    rep, doc, _ = report
    jsonschema.validate(doc, _schema("evidence"))
    results = json.loads(pytest_results(pytester, monitor_runs["good"], tmp_path, "-k", "monitor_coverage").read_text())
    jsonschema.validate(results, _schema("requirements"))
    broken = dict(doc, gate={**doc["gate"], "result": "MAYBE"})
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, _schema("evidence"))


def test_traceability_csv_and_relative_paths(report):
    rep, doc, _ = report
    trace = pd.read_csv(rep.out / "traceability.csv", keep_default_na=False)
    assert list(trace.columns) == ["requirement", "test", "outcome", "state", "artefact"]
    assert set(trace["requirement"]) == set(doc["requirements"])
    for rid, entry in doc["requirements"].items():
        rows = trace[trace["requirement"] == rid]
        assert set(rows["state"]) == {entry["state"]}
        assert sorted(t for t in rows["test"] if t) == sorted(t["nodeid"] for t in entry["tests"])
    sums = (rep.out / "SHA256SUMS").read_text()
    assert f"{sha(rep.out / 'traceability.csv')}  traceability.csv" in sums
    from assurance.evidence import ROOT, rel

    assert rel(ROOT / "reports" / "x.csv") == "reports/x.csv" and rel("/elsewhere/x") == "/elsewhere/x"


@pytest.mark.skipif(not weasyprint_ok(), reason="WeasyPrint not installed")
def test_pdf_is_pdf_a_3b_with_the_evidence_files_attached(report):
    from assurance.evidence import pdf_attachment_names

    rep, _, _ = report
    data = rep.pdf.read_bytes()
    assert b"pdfaid" in data or b"pdfaid" in b"".join(_inflated(data))  # the PDF/A identification (XMP)
    names = pdf_attachment_names(rep.pdf)
    assert {"evidence.json", "results.csv", "traceability.csv", "SHA256SUMS"} <= set(names), names
    assert f"{sha(rep.pdf)}  evidence.pdf" in (rep.out / "SHA256SUMS").read_text()


def _inflated(data: bytes) -> list[bytes]:
    import re
    import zlib

    out = []
    for m in re.finditer(rb"stream\r?\n", data):
        try:
            out.append(zlib.decompressobj().decompress(data[m.end():m.end() + 1_000_000]))
        except zlib.error:
            pass
    return out


def test_shipped_waivers_name_an_owner_and_have_not_expired():
    from assurance.evidence import ROOT, load_waivers, waiver_expired

    waivers = load_waivers(ROOT / "assurance" / "waivers.yaml")
    assert waivers and all(w["owner"] and w["tracked_by"] for w in waivers.values())
    assert "EL-R09" not in waivers  # decided on the release run: no waiver needed
    assert not [rid for rid, w in waivers.items() if waiver_expired(w)], "a shipped waiver expired: fix or renew it"


def test_a_demo_sized_run_says_on_page_one_what_it_cannot_decide(report):
    _, _, html = report
    cover = html.split("<nav>")[0]
    assert "A demo-sized run" in cover and "make release-evidence" in cover
    assert "scene(s) per perturbation; the release run" in cover and "has 70" in cover
