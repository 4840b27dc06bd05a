"""Read flight logs (``el.flight.flightlog``) in one streaming pass (two when some records repeat) and in little memory.

Each log is read line by line (a line longer than ``el.flight.flightlog.MAX_RECORD_BYTES`` is passed over without being
held), hashed as it is read, and folded into a :class:`LogSummary`: counts (decisions, refusals, default actions,
deadline overruns, reasons, poses outside the declared domain), fixed-size seeded reservoir samples of the frame
gate's scores, the monitor's candidate scores and the decision times (exact below their capacity), and a timeline of
at most ``2 * MAX_WINDOWS`` windows. Nothing grows with the log but the counters and the records' 8-byte fingerprints
(the duplicate check, below), so a 1 GB log reads in about the memory of a small one.

A damaged line (not UTF-8, not JSON, not a record of this format, a field of the wrong type, too long) is counted
and the first few are named (file and line), never fatal. A record of another system (its network, system file or
frame gate differs from the one expected) stops the read with :class:`OtherSystemError`, one line naming the file,
the line and both identities; so does a log that is not one unbroken chain of records in order, or a record whose
reason and fields disagree (``assurance.inservice.checks``: :class:`~assurance.inservice.checks.LogRefusedError`).
A refusal is counted from the frame gate's own field (``frame_gate.refused``), never from the reason's wording.

Duplicate records (the same frame hash and time: one decision written twice) are counted once and named. Each
record's fingerprint (8 bytes) is kept while the logs are read; when some repeat, the logs are read a second time and
each repeat after the first is left out of the summary. That is the one thing held per record: 8 MB per million.
"""

from __future__ import annotations

import hashlib
import json
import math
import random
import re
from array import array
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from assurance.inservice.checks import Chain, Findings, LogRefusedError, check_record
from el.base import userfiles
from el.flight.flightlog import DOMAIN_VERDICTS, FORMAT, MAX_RECORD_BYTES, MAX_TEXT
from el.geometry.camera import Pose
from el.geometry.odd import OperatingDomain

RESERVOIR = 200_000
"""Values kept per sample (frame-gate scores, candidate scores, decision times): exact below it, a uniform seeded
sample above (1.6 MB each); the two-sample tests and the 95th percentile are computed on it."""
MAX_WINDOWS = 64
"""The timeline keeps between MAX_WINDOWS and 2 * MAX_WINDOWS windows of equal decision counts (merged in pairs)."""
NAMED_DAMAGED = 10
"""Damaged lines named (file:line: problem) per summary; all are counted."""
MAX_MONITORS = 16
"""Distinct monitor configurations counted by name; further ones are counted together (a log flies one)."""
SEED = 20_240_601
IDENTITY_KEYS = ("network_sha256", "system_sha256", "gate_sha256")
MAX_GATE_FILES = 8
"""Distinct gate-file SHA-256 the logs name that are kept (a log flies one gate)."""
_HEX64 = re.compile(r"[0-9a-f]{64}")
DECISION_STAGES = ("segmentation_s", "candidates_s", "overhead_s")
"""The stages of the decision time in-service compares with the run: segmentation, candidates and the walk's
monitoring, as EL-R13 times a decision (reading the frame left out: a file on the ground, a camera in the air)."""
REASON_KINDS = ("accepted", "all_rejected", "no_candidate", "timeout", "out_of_domain", "outside_odd", "fault")


class OtherSystemError(ValueError):
    """A flight log written by another system than the one it is compared with: one line naming both."""


class Reservoir:
    """A uniform sample of at most ``capacity`` values of a stream (Vitter's algorithm R, seeded: deterministic)."""

    def __init__(self, capacity: int = RESERVOIR, seed: int = SEED) -> None:
        self.capacity, self.seen = int(capacity), 0
        self.values: list[float] = []
        self._rng = random.Random(seed)

    def add(self, value: float) -> None:
        self.seen += 1
        if len(self.values) < self.capacity:
            self.values.append(value)
            return
        k = self._rng.randrange(self.seen)
        if k < self.capacity:
            self.values[k] = value


@dataclass
class Window:
    """A stretch of consecutive decisions: its counts and its first and last time (seconds since the epoch)."""

    start_s: float
    end_s: float
    n: int = 0
    refusals: int = 0
    defaults: int = 0
    overruns: int = 0

    def merge(self, other: Window) -> Window:
        return Window(min(self.start_s, other.start_s), max(self.end_s, other.end_s), self.n + other.n,
                      self.refusals + other.refusals, self.defaults + other.defaults, self.overruns + other.overruns)


@dataclass
class Timeline:
    """Rates over time in bounded memory: windows of ``size`` decisions; past ``2 * MAX_WINDOWS`` windows,
    neighbours merge in pairs and ``size`` doubles."""

    size: int = 1
    windows: list[Window] = field(default_factory=list)

    def add(self, t: float, refused: bool, default: bool, overrun: bool) -> None:
        if not self.windows or self.windows[-1].n >= self.size:
            self.windows.append(Window(t, t))
            if len(self.windows) > 2 * MAX_WINDOWS:
                pairs = zip(self.windows[0:-1:2], self.windows[1:-1:2], strict=True)
                self.windows = [a.merge(b) for a, b in pairs] + [self.windows[-1]]
                self.size *= 2
        w = self.windows[-1]
        w.start_s, w.end_s = min(w.start_s, t), max(w.end_s, t)
        w.n, w.refusals, w.defaults, w.overruns = (w.n + 1, w.refusals + refused, w.defaults + default,
                                                   w.overruns + overrun)


@dataclass
class LogSummary:
    """What the logs hold, folded in one pass (see the module docstring)."""

    files: list[dict[str, Any]] = field(default_factory=list)
    records: int = 0
    damaged: int = 0
    damaged_lines: list[str] = field(default_factory=list)
    identity: dict[str, Any] | None = None
    monitors: Counter[str] = field(default_factory=Counter)
    gate_scores: Reservoir = field(default_factory=Reservoir)
    gate_thresholds: set[float] = field(default_factory=set)
    refusals: int = 0
    candidate_scores: Reservoir = field(default_factory=Reservoir)
    judged: int = 0
    rejected: int = 0
    defaults: int = 0
    overruns: int = 0
    times: Reservoir = field(default_factory=Reservoir)
    decision_times: Reservoir = field(default_factory=Reservoir)
    gate_files: set[str] = field(default_factory=set)
    findings: Findings = field(default_factory=Findings)
    reasons: Counter[str] = field(default_factory=Counter)
    domain: Counter[str] = field(default_factory=Counter)
    pose_outside: Counter[str] = field(default_factory=Counter)
    pose_range: dict[str, list[float]] = field(default_factory=dict)
    timeline: Timeline = field(default_factory=Timeline)

    def fresh(self) -> LogSummary:
        """An empty summary with this one's sample capacities (a second reading of the logs)."""
        return LogSummary(gate_scores=Reservoir(self.gate_scores.capacity),
                          candidate_scores=Reservoir(self.candidate_scores.capacity),
                          times=Reservoir(self.times.capacity), decision_times=Reservoir(self.decision_times.capacity))

    def damage(self, where: str, problem: str) -> None:
        self.damaged += 1
        if len(self.damaged_lines) < NAMED_DAMAGED:
            self.damaged_lines.append(f"{where}: {problem}")


def reason_kind(reason: str) -> str:
    """The kind of a decision's reason (:data:`REASON_KINDS`; ``other`` for one this toolkit does not write)."""
    for kind in REASON_KINDS:
        if reason == kind or reason.startswith(kind + ":"):
            return kind
    return "other"


def _lines(path: Path, digest: Any) -> Iterator[tuple[int, bytes | None, str]]:
    """(line number, bytes, the line's SHA-256) of each line of ``path``, hashed into ``digest`` as read; None for a
    line longer than ``MAX_RECORD_BYTES`` (read past in bounded pieces, never held whole, and hashed as read)."""
    # checked on the descriptor read: a regular file, not the auditor's key under another name (a hard link to an
    # archived log is admitted: only parsed records reach the report)
    with userfiles.open_binary(path, what="flight log", hard_links=True) as handle:
        number = 0
        while True:
            line = handle.readline(MAX_RECORD_BYTES + 1)
            if not line:
                return
            number += 1
            digest.update(line)
            own = hashlib.sha256(line)
            if len(line) > MAX_RECORD_BYTES and not line.endswith(b"\n"):
                while line and not line.endswith(b"\n"):  # the rest of the over-long line, piece by piece
                    line = handle.readline(1 << 20)
                    digest.update(line)
                    own.update(line)
                yield number, None, own.hexdigest()
            else:
                yield number, line, own.hexdigest()


def _num(value: Any, what: str, *, null: bool = True) -> float | None:
    if value is None and null:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{what} is not a number")
    return float(value)


def _obj(value: Any, what: str, *, null: bool = False) -> dict[str, Any] | None:
    if value is None and null:
        return None
    if not isinstance(value, dict):
        raise ValueError(f"{what} is not an object")
    return value


def _hash(value: Any, what: str) -> str | None:
    if value is not None and not (isinstance(value, str) and _HEX64.fullmatch(value)):
        raise ValueError(f"{what} is not a SHA-256")
    return value


def _timings(value: Any) -> dict[str, float]:
    """The record's stage timings (seconds), nulls left out."""
    out: dict[str, float] = {}
    for k, v in _obj(value, "timings").items():
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ValueError(f"timings.{str(k)[:40]} is not a number")
        out[k] = float(v)
    return out


def parse_record(line: bytes) -> dict[str, Any]:
    """A record's fields this reader folds, checked (ValueError naming the first problem)."""
    try:
        doc = json.loads(line.decode("utf-8"))
    except UnicodeDecodeError:
        raise ValueError("not UTF-8 text") from None
    except (json.JSONDecodeError, RecursionError):
        raise ValueError("not a JSON record (cut short by a crash, or corrupted)") from None
    doc = _obj(doc, "the line")
    if doc.get("format") != FORMAT:
        raise ValueError(f"format {str(doc.get('format'))[:40]!r}, not {FORMAT}")
    seq = doc.get("seq")
    if isinstance(seq, bool) or not isinstance(seq, int) or seq < 0:
        raise ValueError("seq is not a non-negative integer")
    system = _obj(doc.get("system"), "system")
    identity = {k: system.get(k) for k in IDENTITY_KEYS}
    if any(v is not None and not isinstance(v, str) for v in identity.values()):
        raise ValueError("a system identity is not a string")
    if doc.get("action") not in ("land", "default") or not isinstance(doc.get("reason"), str):
        raise ValueError("action or reason missing")
    gate = _obj(doc.get("frame_gate"), "frame_gate", null=True)
    if gate is not None and not isinstance(gate.get("refused"), bool):
        raise ValueError("frame_gate.refused is not true or false")
    cands = _obj(doc.get("candidates"), "candidates")
    judged = cands.get("judged")
    if not isinstance(judged, list) or not all(isinstance(c, dict) and isinstance(c.get("accepted"), bool)
                                               for c in judged):
        raise ValueError("candidates.judged is not a list of verdicts")
    deadline = _obj(doc.get("deadline"), "deadline")
    pose = _obj(doc.get("pose"), "pose", null=True)
    frame = _obj(doc.get("frame"), "frame")
    verdict = str((_obj(doc.get("domain"), "domain")).get("verdict"))
    return {"identity": identity, "monitor": str(system.get("monitor"))[:MAX_TEXT], "action": doc["action"],
            "reason": doc["reason"], "unix_s": _num(doc.get("unix_s"), "unix_s", null=False), "seq": seq,
            "prev_sha256": _hash(doc.get("prev_sha256"), "prev_sha256"),
            "gate_file_sha256": _hash(system.get("gate_file_sha256"), "system.gate_file_sha256"),
            "frame_sha256": str(frame.get("sha256"))[:64], "gate": gate is not None,
            "refused": gate is not None and gate["refused"],
            "gate_score": None if gate is None else _num(gate.get("score"), "frame_gate.score"),
            "gate_threshold": None if gate is None else _num(gate.get("threshold"), "frame_gate.threshold"),
            "scores": [_num(c.get("score"), "a candidate score") for c in judged],
            "accepted": [c["accepted"] for c in judged],
            "dropped": int(_num(cands.get("dropped", 0), "candidates.dropped") or 0),
            "total_s": _num(deadline.get("total_s"), "deadline.total_s"),
            "budget_s": _num(deadline.get("budget_s"), "deadline.budget_s"),
            "overrun": _flag(deadline.get("overrun", False), "deadline.overrun"),
            "timings": _timings(doc.get("timings", {})),
            "height_m": None if pose is None else _num(pose.get("height_m"), "pose.height_m"),
            "pitch_deg": None if pose is None else _num(pose.get("pitch_deg"), "pose.pitch_deg"),
            "size": (frame.get("width"), frame.get("height")),
            "domain": verdict if verdict in DOMAIN_VERDICTS else "unknown"}


def _flag(value: Any, what: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{what} is not true or false")
    return value


def _check_identity(summary: LogSummary, identity: dict[str, Any], expected: Mapping[str, Any] | None,
                    where: str) -> None:
    """Refuse a record of another system than ``expected`` (or than the logs' first record, without one)."""
    want = dict(expected) if expected is not None else summary.identity
    if want is None:
        summary.identity = identity
        return
    for key in IDENTITY_KEYS:
        if key in want and identity.get(key) != want[key]:
            found, expected_value = (str(v)[:12] if v else "none recorded" for v in (identity.get(key), want[key]))
            raise OtherSystemError(f"{where}: a decision of another system ({key.replace('_', ' ')} {found}, "
                                   f"expected {expected_value}): refused; a flight log is compared only with the "
                                   "certification run of its own system")
    summary.identity = summary.identity or identity


def _pose(summary: LogSummary, rec: Mapping[str, Any], odd: OperatingDomain | None) -> None:
    h, p = rec["height_m"], rec["pitch_deg"]
    for name, value in (("height_m", h), ("pitch_deg", p)):
        if value is not None:
            lo, hi = summary.pose_range.get(name, [value, value])
            summary.pose_range[name] = [min(lo, value), max(hi, value)]
    w, hgt = rec["size"]
    if odd is None or h is None or p is None or not isinstance(w, int) or not isinstance(hgt, int):
        return
    try:
        found = odd.outside(Pose(height_m=h, pitch_deg=p), (w, hgt))
    except ValueError:
        found = "outside_odd: pose unplannable"
    if found:
        summary.pose_outside[found.split(":", 1)[1].split()[0]] += 1


def fold(summary: LogSummary, rec: Mapping[str, Any], odd: OperatingDomain | None, kind: str | None = None) -> None:
    """Add one parsed record to ``summary`` (``kind``: its reason's, :func:`reason_kind`). A refusal is the frame
    gate's own ``refused`` field (``assurance.inservice.checks`` refuses a record whose reason says otherwise)."""
    summary.records += 1
    known = rec["monitor"] in summary.monitors or len(summary.monitors) < MAX_MONITORS
    summary.monitors[rec["monitor"] if known else "(more configurations)"] += 1
    kind = kind or reason_kind(rec["reason"])
    summary.reasons[kind] += 1
    summary.domain[rec["domain"]] += 1
    refused, default, overrun = bool(rec["refused"]), rec["action"] == "default", rec["overrun"]
    summary.refusals += refused
    summary.defaults += default
    summary.overruns += overrun
    if rec["gate_score"] is not None:
        summary.gate_scores.add(rec["gate_score"])
    if rec["gate_threshold"] is not None and len(summary.gate_thresholds) < 8:
        summary.gate_thresholds.add(rec["gate_threshold"])
    if rec.get("gate_file_sha256") and len(summary.gate_files) < MAX_GATE_FILES:
        summary.gate_files.add(rec["gate_file_sha256"])
    for score, accepted in zip(rec["scores"], rec["accepted"], strict=True):
        summary.judged += 1
        summary.rejected += not accepted
        if score is not None:
            summary.candidate_scores.add(score)
    if rec["total_s"] is not None:
        summary.times.add(rec["total_s"])
    if kind != "fault":  # as the run's faulted rows, left out of the decision times compared
        summary.decision_times.add(sum(rec.get("timings", {}).get(k, 0.0) for k in DECISION_STAGES))
    _pose(summary, rec, odd)
    summary.timeline.add(rec["unix_s"], refused, default, overrun)


def fingerprint(rec: Mapping[str, Any]) -> int:
    """A record's decision as 8 bytes: its frame's SHA-256 and its time (two records alike in both are one decision
    written twice)."""
    key = f"{rec['frame_sha256']}|{rec['unix_s']!r}".encode()
    return int.from_bytes(hashlib.blake2b(key, digest_size=8).digest(), "little")


def _read_log(p: Path, summary: LogSummary, expected: Mapping[str, Any] | None, odd: OperatingDomain | None,
              prints: array | None, repeated: set[int], seen: dict[int, str]) -> None:
    """Fold the records of one log into ``summary``, checking each and the chain (``assurance.inservice.checks``);
    ``prints`` collects each record's :func:`fingerprint` (first reading); a record whose fingerprint is in
    ``repeated`` and already ``seen`` is a duplicate, counted once (second reading)."""
    digest, before, damaged = hashlib.sha256(), summary.records, summary.damaged
    size, chain = p.stat().st_size, Chain(str(p))
    for number, line, line_sha in _lines(p, digest):
        where = f"{p}:{number}"
        if line is not None and not line.strip():
            continue
        try:
            if line is None:
                raise ValueError(f"longer than {MAX_RECORD_BYTES} bytes")
            rec = parse_record(line)
        except ValueError as exc:
            summary.damage(where, str(exc))
            chain.line(line_sha)
            continue
        _check_identity(summary, rec["identity"], expected, where)
        kind = reason_kind(rec["reason"])
        check_record(rec, kind, where)
        chain.record(rec, number, summary.findings)
        chain.line(line_sha)
        mark = fingerprint(rec)
        if prints is not None:
            prints.append(mark)
        elif mark in repeated:
            if mark in seen:
                summary.findings.duplicate(where, f"the decision of {seen[mark]} again (frame "
                                                  f"{rec['frame_sha256'][:12]}, time {rec['unix_s']!r}): counted once")
                continue
            seen[mark] = where
        fold(summary, rec, odd, kind)
    summary.files.append({"path": str(p), "sha256": digest.hexdigest(), "bytes": size,
                          "records": summary.records - before, "damaged": summary.damaged - damaged,
                          "first_seq": chain.first_seq, "last_seq": chain.seq, "chain_head": chain.prev_sha256})


def read_logs(paths: Iterable[str | Path], *, expected: Mapping[str, Any] | None = None,
              odd: OperatingDomain | None = None, summary: LogSummary | None = None) -> LogSummary:
    """Fold every record of the logs at ``paths`` into one summary (see the module docstring). ``expected``: the
    identity every record must carry (``IDENTITY_KEYS``; a key left out is not checked); ``odd``: the declared domain
    the poses are checked against. A path that is no regular file raises ``userfiles.UserFileError`` (one line); a
    log of another system, a broken chain or a record that disagrees with itself, ``OtherSystemError`` or
    ``LogRefusedError`` (one line naming the log and the line)."""
    import numpy as np

    summary = summary or LogSummary()
    logs = [Path(p) for p in paths]
    for p in logs:
        problem = userfiles.not_regular(p, what="flight log")
        if problem:
            raise userfiles.UserFileError(problem)
    prints = array("Q")
    for p in logs:
        _read_log(p, summary, expected, odd, prints, set(), {})
    values, counts = np.unique(np.frombuffer(prints, np.uint64), return_counts=True)
    repeated = {int(v) for v in values[counts > 1]}
    del prints
    if repeated:  # read again, each decision counted once
        summary.__dict__.update(summary.fresh().__dict__)
        seen: dict[int, str] = {}
        for p in logs:
            _read_log(p, summary, expected, odd, None, repeated, seen)
    return summary


__all__ = ["DECISION_STAGES", "MAX_WINDOWS", "RESERVOIR", "LogRefusedError", "LogSummary", "OtherSystemError",
           "Reservoir", "Timeline", "fingerprint", "fold", "parse_record", "read_logs", "reason_kind"]
