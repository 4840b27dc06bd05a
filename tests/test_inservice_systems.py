"""Issue 60: ``uav-el in-service`` on the shapes of system file users write, flown and certified through the command
line (with and without ``[targets] time_budget_s`` and ``[in_service]``), and a comparison of like with like: the
run's decision time as flight would have had it, and no candidate of a frame flight would have refused.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from assurance import cli
from assurance.campaign import readouts
from assurance.fault_injection.case import campaign_argv, first_image, run_cli, save_tiny_weights, use_cli
from assurance.inservice.compare import certified

ODD = 'format = "uav-el-system/1"\n\n[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n'
BUDGET = "\n[targets]\ntime_budget_s = 60.0\n"
SPIS = "\n[in_service]\nmax_overrun_rate = 0.1\nmax_default_rate = 0.9\n"


@pytest.fixture(scope="module")
def ws(tmp_path_factory, one_torch_thread):
    """Two small synthetic test scenes and a tiny network's weights."""
    root = tmp_path_factory.mktemp("systems")
    code, _, err = run_cli(cli.main, ["synth", "--out", root / "data", "--split", "test", "--scenes", "2", "--size",
                                      "320x180", "--no-progress"])
    assert code == 0, err
    save_tiny_weights(root / "tiny.pt")
    use_cli(cli.main)
    return root


@pytest.mark.parametrize(("name", "text", "expected"), [
    ("plain", ODD, 0), ("deadline", ODD + BUDGET, 0), ("deadline-and-spis", ODD + BUDGET + SPIS, 1)])
def test_a_system_is_certified_flown_and_compared(ws, tmp_path, monkeypatch, name, text, expected):
    """Certify a system file, fly it (``land --log``: one decision within its deadline, two at a 1 ms budget), compare
    (``in-service``): a file with a deadline no longer stops the comparison; the SPIs it declares are judged."""
    monkeypatch.chdir(tmp_path)
    system = tmp_path / "uav-el.toml"
    system.write_text(text)
    code, _, err = run_cli(cli.main, campaign_argv(ws, tmp_path / "run", "--system", str(system), data=ws / "data",
                                                   weights=ws / "tiny.pt"))
    assert code == 0, err
    land = ["land", first_image(ws), "--weights", ws / "tiny.pt", "--monitor", "lhd", "--system", system,
            "--log", tmp_path / "flight.jsonl"]
    for extra in ([], ["--budget", "0.001"], ["--budget", "0.001"]):
        assert run_cli(cli.main, [*land, *extra])[0] in (0, 3)
    code, out, err = run_cli(cli.main, ["in-service", tmp_path / "flight.jsonl", "--run", tmp_path / "run",
                                        "--system", system, "--out", tmp_path / "out"])
    assert code == expected, err
    doc = json.loads((tmp_path / "out" / "in-service.json").read_text())
    verdicts = {s["key"]: s["verdict"] for s in doc["spis"]}
    assert doc["comparison"]["overrun"]["service"]["k"] == 2 and doc["comparison"]["overrun"]["run"]["n"] == 2
    if "in_service" in text:
        assert verdicts["max_overrun_rate"] == "breach" and "undermined: G-EL-R13" in out
    else:
        assert {verdicts[k] for k in ("max_refusal_rate", "max_default_rate", "max_overrun_rate")} == {"not declared"}
    html = " ".join((tmp_path / "out" / "in-service.html").read_text().split())
    assert "Fisher p = None" not in html
    if doc["comparison"]["monitor"]["rejection"]["p_value"] is None:
        assert "Fisher's exact test: not run" in html
    ending = "the claims below no longer hold as certified." if expected else "no safety performance indicator " \
                                                                              "breached."
    assert f"{ending} 3 decision(s) read from 1 log(s)" in html  # the verdict, then the next sentence
    assert "hash chain verified" in out


def test_a_page_without_a_judged_candidate_says_the_test_was_not_run(ws, tmp_path):
    from assurance.inservice.report import render_html

    side = {"k": 0, "n": 0, "rate": None, "ci": [None, None]}
    empty = {"service": side, "run": {**side, "n": 4, "k": 1, "rate": 0.25, "ci": [0.0, 0.8]}, "p_value": None}
    drift = {"p_value": None, "n_service": 0, "n_run": 4, "why_not": "few", "test": "KS"}
    doc = {"system": "s", "identity": {"network_sha256": "n", "system_sha256": "s", "gate_sha256": "b" * 64,
                                       "gate_file_sha256": "f" * 64},
           "monitor": "lhd", "run": {"path": "r", "digest": "d", "signed_by": "k"}, "logs": [], "records": 12,
           "damaged": 0, "damaged_lines": [], "breaches": ["overrun_rate"], "verdict": "breach", "spis": [],
           "undermined": [], "settings": {"confidence": 0.95},
           "log_checks": {"unlogged": 0, "gaps": [], "clock_back": 0, "clock_lines": [], "duplicates": 0,
                          "duplicate_lines": []},
           "comparison": {"frame_gate": {"refusal": empty, "drift": drift, "thresholds": [],
                                         "file_sha256_in_logs": ["f" * 64]},
                          "monitor": {"rejection": empty, "drift": drift}, "default": empty, "overrun": empty,
                          "decision_time": {"measure": "m", "p95_service_s": None, "p95_run_s": 0.1,
                                            "p95_service_whole_s": None},
                          "reasons": [], "poses": {"observed": {}, "declared": None, "outside": {},
                                                   "outside_total": 0}}}
    html = " ".join(render_html(doc, {"gate": None, "monitor": None, "rates": None}).split())
    assert "None" not in re.sub(r"<[^>]+>", " ", html)
    assert html.count("Fisher's exact test: not run (no decision on a side)") == 4
    assert "no longer hold as certified. 12 decision(s) read" in html
    assert "f" * 64 in html and "b" * 64 in html  # the gate by its file's SHA-256 and its body's, labelled


def test_the_run_is_measured_as_flight_would_have_decided(tmp_path, monkeypatch):
    """Issue 60: the run's decision time is segmentation + candidates + the walk's monitoring, without the stages
    flight skips past a refusal (not the campaign's task time, which judged every candidate); its monitor scores
    leave out the candidates of refused frames; a deadline is judged on read-only pandas arrays."""
    base = {"perturbation": "none", "severity": 0, "monitor": "lhd", "fault": ""}
    images = pd.DataFrame([
        {**base, "key": "a", "reason": "accepted", "action": "land", "segmentation_s": 0.1, "candidates_s": 0.05,
         "overhead_s": 0.02, "total_s": 2.0, "frame_gate_score": 0.5},
        {**base, "key": "b", "reason": "out_of_domain: frame gate", "action": "default", "segmentation_s": 0.1,
         "candidates_s": 0.05, "overhead_s": 0.5, "total_s": 2.5, "frame_gate_score": 3.0},
        {**base, "key": "c", "reason": "outside_odd: height", "action": "default", "segmentation_s": 0.1,
         "candidates_s": 0.05, "overhead_s": 0.5, "total_s": 2.5, "frame_gate_score": np.nan},
        {**base, "key": "d", "reason": "timeout", "action": "default", "segmentation_s": 0.1, "candidates_s": np.nan,
         "overhead_s": np.nan, "total_s": 0.2, "frame_gate_score": 0.4}])
    cands = pd.DataFrame([{**base, "key": k, "rank": r, "score": s, "accepted": a, "examined": e}
                          for k, r, s, a, e in (("a", 0, 0.9, False, True), ("a", 1, 0.1, True, True),
                                                ("a", 2, 0.2, False, False), ("b", 0, 0.95, False, True),
                                                ("b", 1, 0.97, False, True), ("c", 0, 0.99, False, True))])
    monkeypatch.setattr(readouts, "load_table", lambda run, name: {"images": images, "cands": cands}[
        "images" if name == "images" else "cands"])
    cert = certified(tmp_path, "lhd", budget_s=0.15)  # pandas 3: copy-on-write, its arrays read-only
    np.testing.assert_allclose(cert.times, [0.17, 0.1, 0.0, 0.1])
    assert cert.overruns == 2  # "a" over 0.15 s as flight would have run it, "d" a timeout; not "b" at its 2.5 s
    assert cert.judged == 2 and cert.rejected == 1 and sorted(cert.candidate_scores) == [0.1, 0.9]
    assert cert.refusals == 1 and cert.frames == 4


def test_the_flight_log_fault_cases_behave(ws):
    """Fault-table rows L0-L12 (``assurance.fault_injection.flightlog_cases``), replayed as ``make faults`` and CI
    replay them: each refused with one line naming the log and the line, or stated by the report."""
    from assurance.fault_injection import table as fi
    from assurance.fault_injection.flightlog_cases import COPIES, FLIGHTLOG_CASES

    assert {c.id for c in FLIGHTLOG_CASES} <= {c.id for c in fi.CASES}
    rows = {r["case"]: r for r in fi.run_cases(ws, FLIGHTLOG_CASES, main=cli.main)}
    for r in rows.values():
        assert r["result"] == "pass", r
        assert str(ws) not in r["outcome"]
    assert rows["L1-copied-records"]["outcome"].startswith("uav-el in-service: error: WS/fl/copies.jsonl:5: the hash "
                                                           "chain is broken")
    assert rows["L2-renumbered-copies"]["outcome"].startswith(f"{COPIES} duplicate record(s)")
    assert rows["L3-refusal-relabelled"]["outcome"].count("\n") == 0 and "relabelled.jsonl:2:" in \
        rows["L3-refusal-relabelled"]["outcome"]
    for case in ("L0-deadline-system", "L2-renumbered-copies", "L12-same-log-twice"):  # the breach still shows
        assert rows[case]["observed"] == "1"
