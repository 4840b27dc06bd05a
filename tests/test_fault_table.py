"""``uav-el fault-table``: the fault-injection table, and its appendix in the evidence report."""

from __future__ import annotations

import json
import re

import pytest

from assurance.cli import main
from assurance.evidence import generate
from assurance.fault_injection import table as fi
from el.flight.pipeline import DEPLOYED_MONITOR

pytestmark = pytest.mark.usefixtures("one_torch_thread")

FAST = ("H5-negative-seed", "H6-deleted-shard", "H7-overlay-extension", "H8-json-is-a-folder", "H9-foreign-network",
        "B3-missing-weights", "B4-nan-model")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    return fi.build_workspace(tmp_path_factory.mktemp("faults"), main=main)


def test_cases_cover_issue_19_and_bad_inputs():
    ids = [c.id for c in fi.CASES]
    assert len(ids) == len(set(ids))
    assert sum(i.startswith("H") for i in ids) >= 11 and sum(i.startswith("B") for i in ids) >= 4
    for n in range(1, 9):
        assert any(i.startswith(f"H{n}-") for i in ids), n


def test_quick_slice_names_known_cases_of_every_family():
    """``--quick`` (make demo) replays one or two cases of each family, each a case of the table."""
    ids = {c.id for c in fi.CASES}
    assert set(fi.QUICK) <= ids and len(fi.QUICK) < len(ids)
    assert {i[0] for i in fi.QUICK} == {i[0] for i in ids}  # H, B, R, S, G, T


def test_fast_cases_behave_and_the_report_shows_the_appendix(workspace, tmp_path):
    rows = fi.run_cases(workspace, [c for c in fi.CASES if c.id in FAST], main=main)
    assert [r["case"] for r in rows] == list(FAST)
    for r in rows:
        assert tuple(r) == fi.COLUMNS and r["result"] == "pass", r
        assert r["observed"] == r["expected"] and str(workspace) not in r["command"] + r["outcome"]
    by = {r["case"]: r for r in rows}
    assert by["H6-deleted-shard"]["observed"] == "4" and "shard folder missing" in by["H6-deleted-shard"]["outcome"]
    assert "seed must be an integer >= 0" in by["H5-negative-seed"]["outcome"]

    out = tmp_path / "reports"
    rows[0] = {**rows[0], "outcome": "<script>alert('x')</script>"}
    csv_path, md_path = fi.write_table(rows, out / "faults.csv")
    assert fi.read_table(csv_path) == rows and md_path.read_text().count("\n") == len(rows) + 2
    rep = generate(workspace / "run", out, pdf=False, n_boot=20)
    html = rep.html.read_text(encoding="utf-8")
    assert "Appendix: fault injection" in html and "H8-json-is-a-folder" in html
    assert f"This table holds {len(rows)} of the {len(fi.CASES)}" in " ".join(html.split())  # a slice, said so
    assert "<script>alert" not in html and "&lt;script&gt;" in html
    doc = json.loads(rep.json.read_text())
    assert doc["files"]["faults"].endswith("faults.csv")
    assert "faults.csv" in (out / "SHA256SUMS").read_text()
    # no table beside the report: no appendix
    rep = generate(workspace / "run", tmp_path / "bare", pdf=False, n_boot=20)
    assert "Appendix: fault injection" not in rep.html.read_text(encoding="utf-8")


def test_command_writes_csv_and_markdown_and_refuses_bad_options(tmp_path, capsys):
    assert main(["fault-table", "--list"]) == 0
    assert "H3-budget-timeout" in capsys.readouterr().out
    assert main(["fault-table", "--out", str(tmp_path / "f.txt")]) == 2
    assert main(["fault-table", "--cases", "nope", "--out", str(tmp_path / "f.csv")]) == 2
    assert "unknown case(s): nope" in capsys.readouterr().err
    bad = tmp_path / "faults.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a fault-injection table"):
        fi.read_table(bad)


def test_issue_31_cases_behave(workspace):
    """Bounded resources and no silent loss (R1..R15; R6 and R14, which SIGKILL a campaign, run in the table only:
    tests/test_bounds.py and tests/test_workers.py kill one as slow tests)."""
    from assurance.fault_injection.bounds import BOUNDS_CASES

    killed = {"R6-workers-die-with-parent", "R14-dask-workers-die-with-parent"}
    cases = [c for c in BOUNDS_CASES if c.id not in killed]
    assert {c.id for c in BOUNDS_CASES} <= {c.id for c in fi.CASES} and len(BOUNDS_CASES) == 15
    rows = fi.run_cases(workspace, cases, main=main)
    for r in rows:
        assert r["result"] == "pass", r
    by = {r["case"]: r for r in rows}
    assert "refused before decoding" in by["R1-pixel-header"]["outcome"]
    assert "exceeds the" in by["R5-jobs-1000"]["outcome"] and by["R8-colliding-frames"]["outcome"].startswith("2 task")
    deployed = DEPLOYED_MONITOR.rpartition("threshold=")[2]
    outcome = by["R15-card-threshold"]["outcome"]
    assert f"has threshold {deployed}, but its calibration card has threshold 0.9" in outcome


def test_issue_31_signing_cases_behave(workspace):
    """Forged evidence (S1..S3, exit 4 naming what is wrong) and a waiver that cannot stand (S4, exit 1)."""
    from assurance.fault_injection.signing import SIGNING_CASES

    assert {c.id for c in SIGNING_CASES} <= {c.id for c in fi.CASES}
    rows = fi.run_cases(workspace, SIGNING_CASES, main=main)
    for r in rows:
        assert r["result"] == "pass", r
    by = {r["case"]: r for r in rows}
    assert "seq00_900000" in by["S1-fabricated-run"]["outcome"]
    assert "owned by 'nobody'" in by["S4-bogus-waiver"]["outcome"] or "EL-R99" in by["S4-bogus-waiver"]["outcome"]


def test_issue_31_gate_cases_without_a_test_session_behave(workspace):
    """An uncollectable test, an edited manifest, a re-hashed monitor and swapped weights (G2, G6-G8)."""
    from assurance.fault_injection.gate import GATE_CASES

    assert {c.id for c in GATE_CASES} <= {c.id for c in fi.CASES} and len(GATE_CASES) == 9
    fast = ("G2-uncollectable-test", "G6-edited-manifest", "G7-resigned-monitor", "G8-swapped-weights")
    rows = fi.run_cases(workspace, [c for c in GATE_CASES if c.id in fast], main=main)
    for r in rows:
        assert r["result"] == "pass", r
    by = {r["case"]: r for r in rows}
    assert "learned-copy.json: changed since the run was made" in by["G7-resigned-monitor"]["outcome"]


@pytest.mark.slow
def test_issue_31_gate_cases_with_a_test_session_behave(workspace):
    """A deselected test, a weaker registry or targets, a waiver of a pass, EL-R16 on training scenes (each runs
    uav-el verify: slow)."""
    from assurance.fault_injection.gate import GATE_CASES

    slow = ("G1-deselected-test", "G3-weakened-registry", "G4-weakened-targets", "G5-waiver-of-a-pass",
            "G9-el-r16-training-split")
    rows = fi.run_cases(workspace, [c for c in GATE_CASES if c.id in slow], main=main)
    for r in rows:
        assert r["result"] == "pass", r
    assert "weaker than the system" in {r["case"]: r for r in rows}["G3-weakened-registry"]["outcome"]


def test_trust_boundary_cases_behave(workspace):
    """An applicant's templates and files (T1.., T25.., T50..): no code runs, no local file or network URL is read,
    the first page states the gate's own verdict whatever the folder holds (checked on the report each case leaves),
    and a template that loops, allocates or recurses is exit 2 naming it."""
    from assurance.fault_injection.applicant import APPLICANT_CASES

    assert {c.id for c in APPLICANT_CASES} <= {c.id for c in fi.CASES}
    own = [c for c in APPLICANT_CASES if not re.match(r"T[347]\d-", c.id)]  # T30.., T40.., T70..: their own tests
    rows = fi.run_cases(workspace, own, main=main)
    for r in rows:
        assert r["result"] == "pass", r
    assert not (workspace / "T1-executed").exists()
    by = {r["case"]: r for r in rows}
    if "T2-template-file-attachment" in by:  # with the PDF renderer (the pdf extra) installed
        assert (workspace / "rep-attach" / "evidence.pdf").exists()
        assert "stand-in-signing-key" not in (workspace / "rep-attach" / "evidence.html").read_text("utf-8")


def _issue_50_reader_cases():
    from assurance.fault_injection.trust import TRUST_CASES

    return [c for c in TRUST_CASES if c.id[:3] in {f"T3{n}" for n in range(10)}]


@pytest.mark.parametrize("case", _issue_50_reader_cases(), ids=lambda c: c.id)
def test_issue_50_reader_cases_behave(workspace, case):
    """One reader for every applicant file (T30..T39): a link out of a template or label-set folder, a /proc path
    or a FIFO as a recorded model file, a FIFO or /dev/zero as scene meta, a table past its row cap, a module of the
    working folder, braces in a system fact, an impossible waiver date: each behaves (never hangs, never a
    traceback), one line naming the file and the problem where it is refused."""
    assert case.id in {c.id for c in fi.CASES}
    row = fi.run_case(case, workspace, main=main)
    assert row["result"] == "pass", row
    if case.id.startswith("T30"):
        assert "OUTSIDE-SECRET" not in "".join(p.read_text("utf-8") for p in (workspace / "rep-template-link")
                                               .glob("*.html"))
    if case.id.startswith("T34"):
        assert not (workspace / "applicant-cwd" / "IMPORTED").exists()
    if case.id.startswith("T35"):
        html = (workspace / "rep-braces" / "evidence.html").read_text("utf-8")
        assert "Cam {A} {confidence:pct}" in html and "Cam {A} 95%" not in html


def _issue_50_basis_cases():
    from assurance.fault_injection.basis_cases import BASIS_CASES

    return [c for c in BASIS_CASES if c.id[:3] in {f"T4{n}" for n in range(10)}]


@pytest.mark.parametrize("case", _issue_50_basis_cases(), ids=lambda c: c.id)
def test_issue_50_basis_cases_behave(workspace, case):
    """Everything that judged the run is pinned, the basis owns the hazard categories, an acceptance binds its value
    (T40..T49): a label set swapped back after the run is a gate problem naming its file, road declared safe as
    bare_ground is the deviation class:road, a look-alike of road is refused (exit 2), 0.06 does not accept 0.999 and
    a plain --accept-deviation NAME is refused."""
    assert case.id in {c.id for c in fi.CASES}
    row = fi.run_case(case, workspace, main=main)
    assert row["result"] == "pass", row
    if case.id.startswith("T40"):  # the auditor's report says it on its first page too
        html = (workspace / "rep-label-pin" / "evidence.html").read_text("utf-8")
        assert "labels-pinned.yaml: changed since the run was made" in html
