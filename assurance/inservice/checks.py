"""What a flight log must show before its records are counted: each record agrees with itself, and each log is one
unbroken chain of records in order.

A record's reason is a word the flight function wrote beside the fields it wrote it from, so the two must agree: the
frame gate's own ``refused`` field (and its score against its threshold) with an ``out_of_domain`` reason, the action
with the reason, the judged candidates' verdicts with ``accepted`` and ``all_rejected``, the deadline's ``overrun``
with the decision time and the budget, the declared domain's verdict with an ``outside_odd`` reason. A record whose
reason and fields disagree (a refusal relabelled ``all_rejected``, say) is refused, as is a negative time: neither
is something the flight function writes, and counting either would let a relabelled log pass.

Each log is then read as a chain (:class:`Chain`, ``el.flight.flightlog``): every record carries the SHA-256 of the line
before it, and a sequence number one past the record before it. A record whose ``prev_sha256`` is not the SHA-256 of
the line before it (a record removed, inserted, reordered or edited after the flight), or whose sequence number
repeats or goes back, stops the read with :class:`LogRefusedError`, one line naming the log and the line. A sequence
number that skips (a decision whose record the flight function could not write) and a clock that goes back are not
refusals: they are counted and named, and the report states them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

NAMED = 10
"""Lines named per finding (gaps, clock steps back, duplicates); all are counted."""
STOPPED = ("timeout", "fault")
"""Reason kinds of a decision stopped from outside its stages (the deadline, a fault): its gate may have scored a
frame it had no time to refuse."""


class LogRefusedError(ValueError):
    """A flight log that cannot be counted as written by the flight function: one line naming the log, the line
    and the problem (exit 2)."""


def _short(value: Any) -> str:
    return "none" if value is None else str(value)[:12]


def check_record(rec: Mapping[str, Any], kind: str, where: str) -> None:
    """Refuse (:class:`LogRefusedError`) a parsed record (``assurance.inservice.reader.parse_record``) with a
    negative time, or whose reason (of kind ``kind``, ``reader.reason_kind``) and fields disagree."""
    for name, value in (("unix_s", rec["unix_s"]), ("deadline.total_s", rec["total_s"]),
                        ("deadline.budget_s", rec["budget_s"]), *((f"timings.{k}", v)
                                                                   for k, v in rec["timings"].items())):
        if value is not None and value < 0:
            raise LogRefusedError(f"{where}: {name} is negative ({value:g} s): refused; the flight function never "
                                  "writes a negative time")
    problem = disagreement(rec, kind)
    if problem:
        raise LogRefusedError(f"{where}: the reason {rec['reason'][:60]!r} disagrees with the record's own fields "
                              f"({problem}): refused; a reason is written from those fields, never apart from them")


def disagreement(rec: Mapping[str, Any], kind: str) -> str | None:
    """How the record's reason and its fields disagree, or None."""
    gate, refused = rec["gate"], rec["refused"]
    if refused != (kind == "out_of_domain"):
        return f"frame_gate.refused is {'true' if refused else 'false' if gate else 'absent (no gate)'}"
    if gate and rec["gate_score"] is not None and rec["gate_threshold"] is not None and kind not in STOPPED \
            and refused != (rec["gate_score"] > rec["gate_threshold"]):
        return (f"frame_gate.score {rec['gate_score']:.6g} is {'not ' if refused else ''}above its threshold "
                f"{rec['gate_threshold']:.6g}, yet refused is {'true' if refused else 'false'}")
    if (rec["action"] == "land") != (kind == "accepted"):
        return f"the action is {rec['action']!r}"
    listed = any(rec["accepted"])
    if kind == "accepted" and not listed and not rec["dropped"]:
        return "no judged candidate is accepted"
    if kind in ("all_rejected", "out_of_domain", "outside_odd") and listed:
        return "a judged candidate is accepted"
    if kind == "outside_odd" and rec["domain"] != "outside":
        return f"domain.verdict is {rec['domain']!r}"
    budget, total = rec["budget_s"], rec["total_s"]
    overrun = rec["reason"] == "timeout" or (budget is not None and total is not None and total > budget)
    if rec["overrun"] != overrun:
        return (f"deadline.overrun is {'true' if rec['overrun'] else 'false'} with total_s {_short(total)} and "
                f"budget_s {_short(budget)}")
    return None


@dataclass
class Findings:
    """What the chains showed that is stated, not refused: decisions not logged (sequence gaps), the clock going back,
    duplicate records (the same frame hash and time, counted once); each counted, the first :data:`NAMED` named."""

    unlogged: int = 0
    gaps: list[str] = field(default_factory=list)
    clock_back: int = 0
    clock_lines: list[str] = field(default_factory=list)
    duplicates: int = 0
    duplicate_lines: list[str] = field(default_factory=list)

    def gap(self, where: str, missing: int, text: str) -> None:
        self.unlogged += missing
        if len(self.gaps) < NAMED:
            self.gaps.append(f"{where}: {text}")

    def back(self, where: str, text: str) -> None:
        self.clock_back += 1
        if len(self.clock_lines) < NAMED:
            self.clock_lines.append(f"{where}: {text}")

    def duplicate(self, where: str, text: str) -> None:
        self.duplicates += 1
        if len(self.duplicate_lines) < NAMED:
            self.duplicate_lines.append(f"{where}: {text}")

    def to_dict(self) -> dict[str, Any]:
        return {"unlogged": self.unlogged, "gaps": list(self.gaps), "clock_back": self.clock_back,
                "clock_lines": list(self.clock_lines), "duplicates": self.duplicates,
                "duplicate_lines": list(self.duplicate_lines)}


@dataclass
class Chain:
    """One log read as a chain: the SHA-256 of its last line, its last record's sequence number, line and time."""

    path: str
    prev_sha256: str | None = None
    seq: int | None = None
    first_seq: int | None = None
    seq_line: int = 0
    unix_s: float | None = None
    records: int = 0

    def line(self, digest: str) -> None:
        """A non-empty line was read (a record or a damaged line): the next record chains to it."""
        self.prev_sha256 = digest

    def record(self, rec: Mapping[str, Any], number: int, findings: Findings) -> None:
        """Check a record's place in the chain (refusing a broken chain or a sequence that repeats or goes back;
        counting a gap or a clock going back), then take it as the chain's head."""
        where = f"{self.path}:{number}"
        if rec["prev_sha256"] != self.prev_sha256:
            before = "the log's start" if self.prev_sha256 is None else f"SHA-256 {self.prev_sha256[:12]}"
            raise LogRefusedError(
                f"{where}: the hash chain is broken: the record chains to {_short(rec['prev_sha256'])}, the line "
                f"before it is {before}: a record was removed, inserted, reordered or edited after the flight; "
                "refused")
        seq = rec["seq"]
        if self.seq is None:
            if seq:
                findings.gap(where, seq, f"the log's first record is number {seq}: {seq} decision(s) before it are "
                                         "not in this log")
        elif seq <= self.seq:
            what = "repeats" if seq == self.seq else "goes back"
            raise LogRefusedError(f"{where}: the sequence number {what} ({seq} after {self.seq} at line "
                                  f"{self.seq_line}): refused; a log's records are numbered in the order written")
        elif seq > self.seq + 1:
            missing = seq - self.seq - 1
            findings.gap(where, missing, f"{missing} decision(s) not logged (sequence {self.seq} to {seq})")
        if self.unix_s is not None and rec["unix_s"] < self.unix_s:
            findings.back(where, f"the clock goes back {self.unix_s - rec['unix_s']:.6g} s")
        self.first_seq = seq if self.first_seq is None else self.first_seq
        self.seq, self.seq_line, self.unix_s = seq, number, rec["unix_s"]
        self.records += 1


__all__ = ["NAMED", "STOPPED", "Chain", "Findings", "LogRefusedError", "check_record", "disagreement"]
