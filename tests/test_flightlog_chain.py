"""The flight log as a hash chain (``el.flight.flightlog``) and what ``assurance.inservice.reader`` checks before it
counts a
record (issue 57): the chain and the sequence numbers, duplicates counted once, a refusal taken from the gate's own
fields, a reason that disagrees with them and a negative time refused. No campaign: records of hand-made decisions.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from assurance.inservice import spi
from assurance.inservice.checks import LogRefusedError
from assurance.inservice.compare import rate
from assurance.inservice.reader import read_logs
from el.base.decision import Candidate, Decision, Disc, MonitorVerdict
from el.flight import flightlog
from el.flight.flightlog import FlightLog, log_tail

SHA = "7e" * 32
GATE = {"kind": "mahalanobis", "score": 0.5, "threshold": 1.0, "sha256": "ab" * 32}


class Seconds:
    """A wall clock one second apart per reading."""

    def __init__(self) -> None:
        self.t = 1_790_000_000.0

    def __call__(self) -> float:
        self.t += 1.0
        return self.t


def decision(reason: str = "all_rejected", *, gate: dict | None = GATE, frame: str = "0" * 64) -> Decision:
    """A decision as the kernel makes it, with a frame gate (``gate``: its record; None: no gate): ``accepted``
    lands on its one judged candidate, an ``out_of_domain`` reason comes with a gate score above its threshold."""
    accepted = reason == "accepted"
    judged = [] if reason.startswith("out_of_domain") else [
        Candidate(0, 10.0, 20.0, 5.0, 0.1, 0.1, 0.0, MonitorVerdict("lhd", accepted, "hazard", 0.01, 0.4, 0.5))]
    return Decision(action="land" if accepted else "default", reason=reason, selected=0 if accepted else None,
                    candidates=judged, default_area=Disc(64.0, 60.0, 8.0, "nearest_ground"),
                    timings={"segmentation_s": 0.1, "candidates_s": 0.02, "overhead_s": 0.01, "total_s": 0.2},
                    input={"width": 128, "height": 72, "sha256": frame, "frame_gate": gate,
                           "pose": {"height_m": 50.0, "pitch_deg": 45.0, "source": "frame"}},
                    config={"monitor": "lhd", "time_budget_s": 1.0})


def refusal() -> Decision:
    return decision("out_of_domain: frame gate mahalanobis score 3 > threshold 1", gate={**GATE, "score": 3.0})


CLOCK = Seconds()
"""One clock for every flight of this module: no two decisions share a time (two that did, on one frame, would be
one decision written twice)."""


def fly(path: Path, decisions: list[Decision]) -> Path:
    with FlightLog(path, network_sha256=SHA, fsync=False, clock=CLOCK) as log:
        for d in decisions:
            assert log.write(d), log.last_error
    return path


def records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def write(path: Path, recs: list[dict], *, rechain: bool = True) -> Path:
    """Records as log lines; ``rechain``: each one chained to the line before it, as a forger who knows the format
    would (else written as they are)."""
    prev, out = None, []
    for rec in recs:
        line = json.dumps({**rec, "prev_sha256": prev} if rechain else rec, separators=(",", ":")) + "\n"
        prev = hashlib.sha256(line.encode()).hexdigest()
        out.append(line)
    path.write_text("".join(out))
    return path


def test_a_log_reopened_and_cut_by_a_crash_is_one_chain(tmp_path):
    path = fly(tmp_path / "a.jsonl", [decision(), decision("accepted")])
    fly(path, [decision()])  # reopened: the sequence continues, the first new record chains to the last line
    with open(path, "ab") as f:
        f.write(b'{"format": "uav-el-flight-log/2", "se')  # a crash mid-record
    fly(path, [refusal()])
    lines = path.read_bytes().splitlines(keepends=True)
    recs = [json.loads(line) for line in lines if line.startswith(b'{"format":"')]
    assert [r["seq"] for r in recs] == [0, 1, 2, 3]
    assert recs[0]["prev_sha256"] is None
    assert recs[3]["prev_sha256"] == hashlib.sha256(lines[3]).hexdigest()  # the damaged line, ended by the reopening
    summary = read_logs([path])
    assert summary.records == 4 and summary.damaged == 1 and summary.refusals == 1
    assert summary.findings.to_dict()["unlogged"] == summary.findings.duplicates == summary.findings.clock_back == 0
    assert summary.files[0]["first_seq"] == 0 and summary.files[0]["last_seq"] == 3
    assert summary.files[0]["chain_head"] == hashlib.sha256(lines[-1]).hexdigest() == log_tail(path)[0]


def test_a_failed_write_leaves_a_counted_gap_and_the_chain_whole(tmp_path):
    path = tmp_path / "gap.jsonl"
    with FlightLog(path, network_sha256=SHA, fsync=False, clock=CLOCK) as log:
        assert log.write(decision())
        real = log._file

        class Full:
            def write(self, line: str) -> None:
                real.write(line[:20])  # the disk fills mid-record
                raise OSError("No space left on device")

        log._file = Full()
        assert log.write(decision()) is False and log.failures == 1
        log._file = real
        assert log.write(decision("accepted"))  # resynchronised from the file: the cut line ended, chained to
    summary = read_logs([path])
    assert summary.records == 2 and summary.damaged == 1
    assert summary.findings.unlogged == 1 and "1 decision(s) not logged (sequence 0 to 2)" in summary.findings.gaps[0]


def _removed(r):
    return [r[0], *r[2:]]


def _reordered(r):
    return [r[0], r[2], r[1], *r[3:]]


def _seq_back(r):
    return [*r[:3], {**r[3], "seq": 1}]


def _relabelled(r):
    return [r[0], {**r[1], "reason": "all_rejected"}, *r[2:]]


def _unrefused(r):
    return [r[0], {**r[1], "frame_gate": {**r[1]["frame_gate"], "refused": False}, "reason": "all_rejected"}, *r[2:]]


def _landed(r):
    return [{**r[0], "action": "land"}, *r[1:]]


def _accept_all_rejected(r):
    return [r[0], r[1], {**r[2], "reason": "all_rejected"}, *r[3:]]


def _no_overrun(r):
    return [{**r[0], "deadline": {**r[0]["deadline"], "total_s": 5.0}}, *r[1:]]


def _negative(field):
    def edit(r):
        rec = r[2]
        if field == "unix_s":
            return [*r[:2], {**rec, "unix_s": -1.0}, *r[3:]]
        return [*r[:2], {**rec, "timings": {**rec["timings"], field: -0.01}}, *r[3:]]
    return edit


@pytest.mark.parametrize(("edit", "rechain", "line", "words"), [
    (_removed, False, 2, "the hash chain is broken"),
    (_reordered, False, 2, "the hash chain is broken"),
    (lambda r: [*r[:2], r[0], *r[2:]], False, 3, "the hash chain is broken"),  # a copy inserted
    (lambda r: r[1:], False, 1, "the line before it is the log's start"),  # the head cut off
    (_seq_back, True, 4, "the sequence number goes back (1 after 2 at line 3)"),
    (lambda r: [*r[:2], {**r[2], "seq": 1}, *r[3:]], True, 3, "the sequence number repeats"),
    (_relabelled, True, 2, "the reason 'all_rejected' disagrees with the record's own fields (frame_gate.refused is "
                           "true)"),
    (_unrefused, True, 2, "frame_gate.score 3 is above its threshold 1, yet refused is false"),
    (lambda r: [r[0], {**r[1], "frame_gate": None}, *r[2:]], True, 2, "frame_gate.refused is absent (no gate)"),
    (lambda r: [r[0], {**r[1], "frame_gate": {**r[1]["frame_gate"], "score": 0.5}}, *r[2:]], True, 2,
     "frame_gate.score 0.5 is not above its threshold 1, yet refused is true"),
    (_landed, True, 1, "(the action is 'land')"),
    (_accept_all_rejected, True, 3, "(the action is 'land')"),
    (_no_overrun, True, 1, "deadline.overrun is false with total_s 5.0 and budget_s 1.0"),
    (_negative("unix_s"), True, 3, "unix_s is negative"),
    (_negative("segmentation_s"), True, 3, "timings.segmentation_s is negative"),
])
def test_an_edited_log_is_refused_naming_the_line(tmp_path, edit, rechain, line, words):
    path = fly(tmp_path / "good.jsonl", [decision(), refusal(), decision("accepted"), decision(gate=GATE)])
    edited = write(tmp_path / "edited.jsonl", edit(records(path)), rechain=rechain)
    with pytest.raises(LogRefusedError) as err:
        read_logs([edited])
    message = str(err.value)
    assert message.startswith(f"{edited}:{line}: ") and words in message and "\n" not in message


def test_copies_of_a_good_record_are_counted_once_and_named(tmp_path):
    """Issue 57: 3 000 copies of one good record no longer dilute a refusal-rate breach."""
    path = fly(tmp_path / "log.jsonl", [refusal(), refusal(), refusal(), decision("accepted", frame="1" * 64)])
    recs = records(path)
    forged = write(tmp_path / "forged.jsonl", recs + [{**recs[3], "seq": 4 + i} for i in range(3000)])
    summary = read_logs([forged])
    assert summary.records == 4 and summary.refusals == 3 and summary.findings.duplicates == 3000
    assert summary.findings.duplicate_lines[0] == (f"{forged}:5: the decision of {forged}:4 again (frame 111111111111, "
                                                   f"time {recs[3]['unix_s']!r}): counted once")
    comparison = {"frame_gate": {"refusal": rate(summary.refusals, summary.records, 0, 24)}}
    judged = spi._rate(comparison["frame_gate"]["refusal"], 0.1, 0.95, 1)
    assert judged[0] == spi.BREACH  # 3 of 4, as flown
    twice = read_logs([path, path])  # the same log given twice
    assert twice.records == 4 and twice.findings.duplicates == 4


def test_a_clock_going_back_is_stated_not_refused(tmp_path):
    recs = records(fly(tmp_path / "log.jsonl", [decision(), decision(), decision()]))
    path = write(tmp_path / "back.jsonl", [*recs[:2], {**recs[2], "unix_s": recs[0]["unix_s"] - 10.0}])
    summary = read_logs([path])
    assert summary.records == 3 and summary.findings.clock_back == 1
    assert summary.findings.clock_lines == [f"{path}:3: the clock goes back 11 s"]


def test_a_refusal_is_counted_from_the_gates_own_field(tmp_path):
    summary = read_logs([fly(tmp_path / "log.jsonl", [refusal(), decision(gate=GATE), refusal()])])
    assert summary.refusals == 2 and summary.reasons["out_of_domain"] == 2


def test_decisions_not_logged_are_judged_both_ways():
    """A pass must hold were every unlogged decision an event, a breach were none; else undecided."""
    def verdict(k, n, gaps):
        return spi._rate(rate(k, n, 0, 10, unlogged=gaps), 0.1, 0.95, 1)[0]

    assert verdict(0, 100, 0) == spi.PASS and verdict(0, 100, 20) == spi.UNDECIDED
    assert verdict(30, 40, 0) == spi.BREACH and verdict(30, 40, 5) == spi.BREACH
    assert verdict(5, 20, 0) == spi.BREACH and verdict(5, 20, 40) == spi.UNDECIDED


def test_the_gate_file_is_named_by_its_own_sha256(tmp_path):
    gate_file = tmp_path / "gate.json"
    gate_file.write_text('{"body": {}}')
    d = decision(gate=GATE)
    d.config["gate"] = str(gate_file)
    rec = records(fly(tmp_path / "log.jsonl", [d]))[0]
    assert rec["system"]["gate_file_sha256"] == hashlib.sha256(gate_file.read_bytes()).hexdigest()
    assert rec["system"]["gate_sha256"] == GATE["sha256"]  # the body's, as the run's manifest records it
    assert records(fly(tmp_path / "none.jsonl", [decision(gate=None)]))[0]["system"]["gate_file_sha256"] is None


def test_the_tail_of_a_long_log_is_found_past_the_block_read(tmp_path, monkeypatch):
    path = fly(tmp_path / "log.jsonl", [decision() for _ in range(5)])
    monkeypatch.setattr(flightlog, "TAIL_BYTES", 64)  # shorter than one record: the whole log is read
    lines = path.read_bytes().splitlines(keepends=True)
    assert log_tail(path) == (hashlib.sha256(lines[-1]).hexdigest(), 5)
    fly(path, [decision()])
    assert read_logs([path]).records == 6
