"""Fault-injection cases of the flight log read in service (rows ``L0``..``L12``): a breach hidden in the logs
(records copied in, a refusal relabelled, a negative time), records removed, inserted, reordered or cut off the log's
head after the flight, sequence numbers that repeat, skip or run back with the clock, and the same log given twice.

Each case flies the workspace's tiny network through ``uav-el land --log`` against a certification run of a system
file that declares a deadline (``[targets] time_budget_s``) and an overrun SPI (``[in_service] max_overrun_rate``),
then edits a copy of the log as an operator could and runs ``uav-el in-service`` on it. The base log holds one decision
within its deadline and three at a 1 ms budget (overruns): three of four breach the SPI, so a case whose edit would
hide the breach shows whether it is hidden. What the hash chain cannot show (records cut off the log's end, a whole
log written by something else) has no row: ``docs/operate.md`` says so.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from assurance.fault_injection.case import Case, campaign_argv, first_image, prepare

SYSTEM = ('format = "uav-el-system/1"\n\n[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n\n'
          "[targets]\ntime_budget_s = 60.0\n\n[in_service]\nmax_overrun_rate = 0.1\n")
"""The flown system: small frames admitted, a deadline, an overrun SPI."""
COPIES = 3000


def _flown(ws: Path) -> tuple[Path, Path]:
    """The certification run of the flown system (``WS/fl-run``) and its base flight log (``WS/fl/base.jsonl``),
    made once per workspace through the command line."""
    folder, run, base = ws / "fl", ws / "fl-run", ws / "fl" / "base.jsonl"
    if base.is_file() and (run / "manifest.json").is_file():
        return run, base
    folder.mkdir(exist_ok=True)
    system = folder / "uav-el.toml"
    system.write_text(SYSTEM, encoding="utf-8")
    if prepare(campaign_argv(ws, run, "--system", str(system))):
        raise RuntimeError("flight-log cases: the certification campaign of the flown system failed")
    land = ["land", first_image(ws), "--weights", ws / "tiny.pt", "--monitor", "lhd", "--system", system,
            "--log", base]
    for extra in ([], ["--budget", "0.001"], ["--budget", "0.001"], ["--budget", "0.001"]):
        if prepare([*land, *extra]) not in (0, 3):
            raise RuntimeError("flight-log cases: uav-el land --log failed")
    return run, base


def _records(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]


def _write(path: Path, records: list[dict[str, Any]], *, rechain: bool) -> None:
    """The records as log lines; ``rechain``: each one's ``prev_sha256`` made the SHA-256 of the line before it, as a
    forger who knows the format would (else the records are written as they are)."""
    prev, lines = None, []
    for rec in records:
        if rechain:
            rec = {**rec, "prev_sha256": prev}
        line = json.dumps(rec, separators=(",", ":"), ensure_ascii=False) + "\n"
        prev = hashlib.sha256(line.encode("utf-8")).hexdigest()
        lines.append(line)
    path.write_text("".join(lines), encoding="utf-8")


def _edited(name: str, edit: Callable[[list[dict[str, Any]]], list[dict[str, Any]]], *, rechain: bool,
            twice: bool = False) -> Callable[[Path], list[str]]:
    """A case's ``make``: a copy of the base log edited by ``edit``, then ``uav-el in-service`` on it."""

    def make(ws: Path) -> list[str]:
        run, base = _flown(ws)
        log = ws / "fl" / f"{name}.jsonl"
        if edit is _same:
            shutil.copy(base, log)
        else:
            _write(log, edit(_records(base)), rechain=rechain)
        logs = [log, log] if twice else [log]
        return ["in-service", *logs, "--run", run, "--system", ws / "fl" / "uav-el.toml", "--out",
                ws / "fl" / f"out-{name}"]

    return make


def _same(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return records


def _copies(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return records + [dict(records[0]) for _ in range(COPIES)]


def _copies_renumbered(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    last = records[-1]["seq"]
    return records + [{**records[0], "seq": last + 1 + i} for i in range(COPIES)]


def _relabelled(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    refused = {**records[1], "reason": "all_rejected",
               "frame_gate": {"kind": "mahalanobis", "score": 9.0, "threshold": 1.0, "refused": True}}
    return [records[0], refused, *records[2:]]


def _negative_time(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rec = records[0]
    return [{**rec, "deadline": {**rec["deadline"], "total_s": -0.5}}, *records[1:]]


def _removed(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [records[0], *records[2:]]


def _inserted(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [*records[:2], {**records[0], "unix_s": records[1]["unix_s"]}, *records[2:]]


def _reordered(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [records[0], records[2], records[1], *records[3:]]


def _head_cut(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return records[1:]


def _seq_repeats(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [records[0], records[1], {**records[2], "seq": records[1]["seq"]}, *records[3:]]


def _seq_gap(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [*records[:-1], {**records[-1], "seq": records[-1]["seq"] + 5}]


def _clock_back(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [*records[:-1], {**records[-1], "unix_s": records[0]["unix_s"] - 3600.0}]


FLIGHTLOG_CASES: tuple[Case, ...] = (
    Case("L0-deadline-system", "in-service on a system file with [targets] time_budget_s (issue 60: 'output array "
         "is read-only'): 3 of 4 decisions overran", _edited("same", _same, rechain=False), 1,
         "undermined: G-EL-R13", "overrun_rate"),
    Case("L1-copied-records", f"{COPIES} copies of one good record appended to dilute the overrun breach",
         _edited("copies", _copies, rechain=False), 2, "the hash chain is broken"),
    Case("L2-renumbered-copies", f"{COPIES} copies of one good record, renumbered and re-chained by a forger "
         "(same frame hash and time)", _edited("renumbered", _copies_renumbered, rechain=True), 1,
         f"{COPIES} duplicate record(s)", "duplicate record"),
    Case("L3-refusal-relabelled", "a record the frame gate refused (frame_gate.refused true) relabelled "
         "'all_rejected', the chain re-made", _edited("relabelled", _relabelled, rechain=True), 2,
         "disagrees with the record's own fields (frame_gate.refused is true)"),
    Case("L4-negative-time", "a record's decision time set to -0.5 s, the chain re-made",
         _edited("negative", _negative_time, rechain=True), 2, "deadline.total_s is negative"),
    Case("L5-record-removed", "the second record deleted after the flight",
         _edited("removed", _removed, rechain=False), 2, "the hash chain is broken"),
    Case("L6-record-inserted", "a record inserted after the flight", _edited("inserted", _inserted, rechain=False),
         2, "the hash chain is broken"),
    Case("L7-records-reordered", "two records swapped after the flight",
         _edited("reordered", _reordered, rechain=False), 2, "the hash chain is broken"),
    Case("L8-head-cut", "the log's first record cut off", _edited("head", _head_cut, rechain=False), 2,
         "the line before it is the log's start"),
    Case("L9-sequence-repeats", "a record's sequence number set to the one before it, the chain re-made",
         _edited("repeats", _seq_repeats, rechain=True), 2, "the sequence number repeats"),
    Case("L10-sequence-gap", "five sequence numbers skipped before the last record (records not written), the chain "
         "re-made: the overrun SPI judged with them as overruns and as none", _edited("gap", _seq_gap, rechain=True),
         0, "5 decision(s) not logged", "not logged"),
    Case("L11-clock-back", "the last record's time an hour before the first's, the chain re-made",
         _edited("clock", _clock_back, rechain=True), 1, "clock goes back", "clock goes back"),
    Case("L12-same-log-twice", "the same flight log given twice", _edited("twice", _same, rechain=False, twice=True),
         1, "4 duplicate record(s)", "duplicate record"),
)
"""The flight-log cases, in table order."""
