"""The flight log: one JSON line per decision, appended as it is made, for in-service evidence (``uav-el in-service``).

Opt-in: a flight function given a :class:`FlightLog` (``EmergencyLanding(..., log=FlightLog(path))``,
``uav-el land --log FILE``) calls :meth:`FlightLog.write` after each decision. A record holds what a certificate's
assumptions can be checked against in service, never the frame itself (its SHA-256 only; a sample of frames on
request): the time, the frame's hash and size, the pose and its source, the declared domain's verdict, the frame
gate's score and threshold, the candidate count and each judged candidate's monitor score and verdict, the action,
reason and default-area basis, the stage timings and the deadline, and the system's identity (network,
system-file and frame-gate SHA-256). The format is versioned (:data:`FORMAT`) and described by
``el/data/flightlog.schema.json``.

A hash chain: each record carries the SHA-256 of the line before it in the file (``prev_sha256``; null for a log's
first line) and a sequence number that continues over every opening of the log (``seq``), so that a record removed,
inserted, reordered or edited after the flight breaks the chain at the line after it (``uav-el in-service`` names
that line). The chain proves the lines are the ones written in that order; it does not prove that the writer was
this flight function (an operator can write a whole false log), nor that no record was cut off the log's end.

Append-only and crash-safe: each record is written whole with one ``write``, then flushed and (by default)
``fsync``-ed, so a crash loses at most the record being written and leaves at most one damaged last line, which a
reader counts and passes over; a log reopened after such a crash starts on a new line. Every record is at most
:data:`MAX_RECORD_BYTES` long (reasons cut, judged candidates past :data:`MAX_LOGGED_CANDIDATES` counted, not
listed). Fail safe: :meth:`FlightLog.write` never raises; a failure is counted (``failures``, ``last_error``) and
logged once, and the decision stands.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path
from typing import IO, Any

import numpy as np

from el.base.decision import Decision, _finite
from el.base.hashing import sha256_file
from el.geometry.camera import Pose
from el.geometry.odd import OUTSIDE_ODD, OperatingDomain
from el.monitors.frame_gate import OUT_OF_DOMAIN

FORMAT = "uav-el-flight-log/2"
"""The record format: a reader refuses records of another major version (2: the hash chain, ``prev_sha256``;
``seq`` continued over reopenings; the frame gate's file SHA-256, ``gate_file_sha256``)."""
MAX_RECORD_BYTES = 16 * 1024
"""The longest record line, in UTF-8 bytes, newline included (a decision with 64 judged candidates takes ~6 kB)."""
MAX_LOGGED_CANDIDATES = 64
"""Judged candidates listed per record; more are counted in ``candidates.dropped``."""
MAX_TEXT = 240
"""Characters kept of a reason or a monitor name (a fault's message can be long)."""
TIMING_KEYS = ("read_s", "segmentation_s", "candidates_s", "monitoring_s", "overhead_s", "total_s")
"""The stage timings a record keeps (seconds)."""
DOMAIN_VERDICTS = ("inside", "outside", "not_declared", "unknown")
TAIL_BYTES = 4 << 20
"""How much of a log's end is read when it is reopened, to find the last line (chained to) and the last sequence
number (continued from); a longer last line, or no record in it, has the whole log read."""
logger = logging.getLogger(__name__)

Clock = Callable[[], float]


def _text(value: Any) -> str | None:
    return None if value is None else str(value)[:MAX_TEXT]


def _num(value: Any) -> float | None:
    """A finite float, else None (JSON has no NaN)."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        return None
    v = float(value)
    return v if math.isfinite(v) else None


def domain_verdict(decision: Decision) -> dict[str, Any]:
    """Whether the decision's frame was inside the declared domain its configuration records (``config.odd``):
    ``outside`` (the flight's own ``outside_odd`` reason, or its pose and size found outside here), ``inside``,
    ``not_declared`` (no domain configured) or ``unknown`` (no pose or size recorded: a frame never read)."""
    reason = decision.reason
    if reason.startswith(OUTSIDE_ODD):
        return {"verdict": "outside", "reason": _text(reason)}
    declared = decision.config.get("odd")
    if not declared:
        return {"verdict": "not_declared", "reason": None}
    pose, info = decision.input.get("pose") or {}, decision.input
    try:
        odd = OperatingDomain.from_dict(declared)
        found = odd.outside(Pose(height_m=float(pose["height_m"]), pitch_deg=float(pose["pitch_deg"])),
                            (int(info["width"]), int(info["height"])))
    except (KeyError, TypeError, ValueError):
        return {"verdict": "unknown", "reason": None}
    return {"verdict": "outside" if found else "inside", "reason": _text(found)}


def _candidates(decision: Decision) -> dict[str, Any]:
    """The candidate count and the judged candidates' monitor scores and verdicts (at most
    :data:`MAX_LOGGED_CANDIDATES`; the rest counted in ``dropped``)."""
    judged = [c for c in decision.candidates if c.monitor is not None]
    listed = [{"rank": int(c.rank), "score": _num(c.monitor.score), "threshold": _num(c.monitor.threshold),
               "accepted": bool(c.monitor.accepted)} for c in judged[:MAX_LOGGED_CANDIDATES]]
    return {"count": len(decision.candidates), "judged": listed, "dropped": max(0, len(judged) - len(listed))}


def _gate(decision: Decision) -> dict[str, Any] | None:
    gate = decision.input.get("frame_gate")
    if not isinstance(gate, Mapping):
        return None

    return {"kind": _text(gate.get("kind")), "score": _num(gate.get("score")),
            "threshold": _num(gate.get("threshold")), "refused": decision.reason.startswith(OUT_OF_DOMAIN)}


def _deadline(decision: Decision) -> dict[str, Any]:
    budget, total = _num(decision.config.get("time_budget_s")), _num(decision.timings.get("total_s"))
    over = decision.reason == "timeout" or (budget is not None and total is not None and total > budget)
    return {"budget_s": budget, "total_s": total, "overrun": bool(over)}


def flight_record(decision: Decision, *, seq: int, unix_s: float, identity: Mapping[str, Any],
                  frame_sample: str | None = None, prev_sha256: str | None = None) -> dict[str, Any]:
    """The log record of one decision (see the module docstring and ``el/data/flightlog.schema.json``):
    ``identity`` holds the system's ``network_sha256``, ``system_sha256`` and, with a gate, ``gate_file_sha256``
    (the gate file's own SHA-256, the one the evidence report names); ``unix_s`` is the wall-clock time;
    ``prev_sha256`` the SHA-256 of the log's line before this record (None: the log's first line)."""
    info, pose, area = decision.input, decision.input.get("pose"), decision.default_area
    stamp = _dt.datetime.fromtimestamp(unix_s, _dt.UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")
    gate = info.get("frame_gate") if isinstance(info.get("frame_gate"), Mapping) else {}
    record: dict[str, Any] = {
        "format": FORMAT, "seq": int(seq), "prev_sha256": prev_sha256, "time": stamp, "unix_s": float(unix_s),
        "system": {"network_sha256": identity.get("network_sha256"), "system_sha256": identity.get("system_sha256"),
                   "monitor": _text(decision.config.get("monitor")), "gate_sha256": gate.get("sha256"),
                   "gate_file_sha256": identity.get("gate_file_sha256") if gate else None,
                   "calibration": _text(decision.config.get("calibration"))},
        "frame": {"sha256": info.get("sha256"), "width": info.get("width"), "height": info.get("height")},
        "pose": None if not isinstance(pose, Mapping) else {
            "height_m": _num(pose.get("height_m")), "pitch_deg": _num(pose.get("pitch_deg")),
            "source": _text(pose.get("source"))},
        "domain": domain_verdict(decision),
        "frame_gate": _gate(decision),
        "candidates": _candidates(decision),
        "action": decision.action, "reason": _text(decision.reason), "selected": decision.selected,
        "default_area": {"x": _num(area.x), "y": _num(area.y), "radius_px": _num(area.radius_px),
                         "basis": area.basis},
        "timings": {k: _num(decision.timings[k]) for k in TIMING_KEYS if k in decision.timings},
        "deadline": _deadline(decision),
    }
    if frame_sample is not None:
        record["frame_sample"] = frame_sample
    return _finite(record)


def record_line(record: Mapping[str, Any]) -> str:
    """One record as its log line (compact JSON, newline-terminated), at most :data:`MAX_RECORD_BYTES` bytes: a record
    still too long once its candidates are capped lists none of them (``dropped`` counts them all)."""
    line = json.dumps(record, separators=(",", ":"), allow_nan=False, ensure_ascii=False) + "\n"
    if len(line.encode("utf-8")) <= MAX_RECORD_BYTES:
        return line
    cands = dict(record["candidates"])
    cands["dropped"], cands["judged"] = int(cands.get("dropped", 0)) + len(cands.get("judged", [])), []
    line = json.dumps({**record, "candidates": cands}, separators=(",", ":"), allow_nan=False,
                      ensure_ascii=False) + "\n"
    if len(line.encode("utf-8")) > MAX_RECORD_BYTES:
        raise ValueError(f"a flight-log record of {len(line)} bytes exceeds {MAX_RECORD_BYTES} bytes")
    return line


class FlightLog:
    """An append-only flight log (see the module docstring).

    Parameters
    ----------
    target : path or writable text file
        A path is opened in append mode (created if missing) and the log continued: its next record chains to the
        file's last line and takes the number after its last record's (:func:`log_tail`). A file object is written
        to as it is (the caller closes it) and taken as a new log: its first record chains to nothing and is number 0,
        so give a path to continue an existing log. One writer per log: two appending to one file at once fork the
        chain, and ``uav-el in-service`` refuses it. A path that cannot be opened is kept as ``fault``: every write
        then fails, counted, and the decisions stand.
    network_sha256, system_sha256 : str or None
        The system's identity: the network's weights SHA-256 (else taken from the segmenter given to
        :meth:`write`) and the system file's SHA-256 (``uav-el.toml``; None when there is none).
    fsync : bool
        ``os.fsync`` after every record (the default: a crash or power loss keeps every record written);
        False: flushed only.
    sample_every, sample_dir : int, path
        Keep every ``sample_every``-th frame as a PNG in ``sample_dir`` for later review (0, the default: no frame
        is kept); the record names the file (``frame_sample``).
    clock : callable returning seconds since the epoch
        The records' wall-clock time (inject one in tests).
    """

    def __init__(self, target: str | Path | IO[str], *, network_sha256: str | None = None,
                 system_sha256: str | None = None, fsync: bool = True, sample_every: int = 0,
                 sample_dir: str | Path | None = None, clock: Clock = time.time) -> None:
        if isinstance(sample_every, bool) or not isinstance(sample_every, int) or sample_every < 0:
            raise ValueError(f"sample_every must be a non-negative integer, got {sample_every!r}")
        if sample_every and sample_dir is None:
            raise ValueError("sample_every needs a sample_dir to keep the frames in")
        self.identity = {"network_sha256": network_sha256, "system_sha256": system_sha256}
        self.fsync, self.clock = bool(fsync), clock
        self.sample_every, self.sample_dir = sample_every, None if sample_dir is None else Path(sample_dir)
        self.seq, self.written, self.failures, self.sample_failures = 0, 0, 0, 0
        self.fault: str | None = None
        self.last_error: str | None = None
        self.prev_sha256: str | None = None  # the SHA-256 of the log's last line: the next record chains to it
        self._gate_files: dict[str, str | None] = {}
        self._resync = False
        self._lock = threading.Lock()
        self._owned = not hasattr(target, "write")
        self.path = Path(target) if self._owned else None  # type: ignore[arg-type]
        self._file: IO[str] | None = None
        try:
            self._file = self._open(Path(target)) if self._owned else target  # type: ignore[arg-type,assignment]
        except (OSError, ValueError) as exc:
            self.fault = f"{target}: cannot open the flight log: {exc}"
            logger.error("%s; decisions go unlogged", self.fault)

    def _open(self, path: Path) -> IO[str]:
        """Open ``path`` for appending: a last line left without its newline (a crash) is ended first, then the next
        record chains to the last line and continues its sequence number (:func:`log_tail`)."""
        handle = open(path, "a", encoding="utf-8")  # noqa: SIM115  (kept open for the flight)
        try:
            self._continue(path, handle)
        except BaseException:
            handle.close()
            raise
        return handle

    def _continue(self, path: Path, handle: IO[str]) -> None:
        """End a cut last line, then take the chain's head and the next sequence number from the file itself."""
        if handle.tell() > 0:
            with open(path, "rb") as raw:
                raw.seek(-1, os.SEEK_END)
                if raw.read(1) != b"\n":
                    handle.write("\n")
                    handle.flush()
        self.prev_sha256, next_seq = log_tail(path)
        self.seq = max(self.seq, next_seq)

    def write(self, decision: Decision, *, segmenter: Any = None, frame: np.ndarray | None = None) -> bool:
        """Append the record of ``decision``; True when it was written. Never raises: a failure (the disk full, the
        file closed, a record that cannot be built) is counted in ``failures`` and ``last_error``, and logged once.
        ``segmenter``: the network that decided (its ``weights_sha256`` is the identity when none was given);
        ``frame``: the decided frame, kept as a sample when sampling is on."""
        with self._lock:
            try:
                if self._resync and self._owned and self._file is not None and self.path is not None:
                    self._continue(self.path, self._file)  # after a failed write: the file says where it stands
                    self._resync = False
            except Exception:  # noqa: S110  (the write below fails and is counted)
                pass
            seq = self.seq
            self.seq += 1  # a decision whose record fails leaves its number unused: a gap the reader counts
            try:
                if self._file is None:
                    raise OSError(self.fault or "the flight log is closed")
                identity = dict(self.identity, gate_file_sha256=self._gate_file(decision))
                if identity["network_sha256"] is None:
                    identity["network_sha256"] = _weights_sha256(segmenter)
                sample = self._sample_safely(seq, decision, frame)
                line = record_line(flight_record(decision, seq=seq, unix_s=float(self.clock()), identity=identity,
                                                 frame_sample=sample, prev_sha256=self.prev_sha256))
                self._file.write(line)
                self._file.flush()
                self.prev_sha256 = hashlib.sha256(line.encode("utf-8")).hexdigest()
                if self.fsync:
                    os.fsync(self._file.fileno())
            except Exception as exc:  # fail safe: the decision stands, unlogged
                self._resync = True
                self.failures += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                if self.failures == 1:
                    logger.error("flight log: a record could not be written (%s); counting further failures",
                                 self.last_error)
                return False
            self.written += 1
            return True

    def _gate_file(self, decision: Decision) -> str | None:
        """The SHA-256 of the frame-gate file the decision's configuration names (``config.gate``), hashed once per
        path; None without a gate or when it cannot be read (the record's ``gate_sha256``, its body's, still names
        it)."""
        path = decision.config.get("gate")
        if not isinstance(path, str | os.PathLike):
            return None
        key = str(path)
        if key not in self._gate_files:
            try:
                self._gate_files[key] = sha256_file(Path(key), what="frame gate", max_bytes=64 << 20)
            except (OSError, ValueError):  # missing, or refused by the bounded reader (a FIFO, too large)
                self._gate_files[key] = None
        return self._gate_files[key]

    def _sample_safely(self, seq: int, decision: Decision, frame: np.ndarray | None) -> str | None:
        """:meth:`_sample`, a failure counted in ``sample_failures`` (the record is still written, without it)."""
        try:
            return self._sample(seq, decision, frame)
        except Exception as exc:
            self.sample_failures += 1
            if self.sample_failures == 1:
                logger.error("flight log: a frame sample could not be kept (%s: %s)", type(exc).__name__, exc)
            return None

    def _sample(self, seq: int, decision: Decision, frame: np.ndarray | None) -> str | None:
        """Keep the frame as a PNG named by its SHA-256 when this record is sampled; the file's name, else None."""
        if not self.sample_every or seq % self.sample_every or not isinstance(frame, np.ndarray) \
                or self.sample_dir is None:
            return None
        import cv2

        name = f"{str(decision.input.get('sha256') or seq)[:32]}.png"
        ok, data = cv2.imencode(".png", np.ascontiguousarray(frame[..., ::-1]))
        if not ok:
            raise ValueError("the frame sample could not be encoded as PNG")
        self.sample_dir.mkdir(parents=True, exist_ok=True)
        (self.sample_dir / name).write_bytes(data.tobytes())
        return name

    def close(self) -> None:
        """Close a log opened from a path (a file object given is the caller's to close)."""
        with self._lock:
            if self._owned and self._file is not None:
                self._file.close()
            self._file = None

    def __enter__(self) -> FlightLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _last_lines(data: bytes) -> list[bytes]:
    """The non-empty lines of ``data``, newline kept, last first."""
    return [ln for ln in reversed(data.splitlines(keepends=True)) if ln.strip()]


def _next_seq(lines: list[bytes]) -> int | None:
    """One past the sequence number of the latest record among ``lines`` (last first); None when none is one."""
    for line in lines:
        try:
            doc = json.loads(line)
        except (ValueError, RecursionError):
            continue
        seq = doc.get("seq") if isinstance(doc, dict) and doc.get("format") == FORMAT else None
        if isinstance(seq, int) and not isinstance(seq, bool) and seq >= 0:
            return seq + 1
    return None


def log_tail(path: str | Path) -> tuple[str | None, int]:
    """(the SHA-256 of the log's last non-empty line, the sequence number its next record takes) of the log at
    ``path``: (None, 0) for an empty or new log. Reads the last :data:`TAIL_BYTES`; the whole log, in bounded pieces,
    when the last line or the last record lies before them."""
    p = Path(path)
    if not p.is_file() or p.stat().st_size == 0:
        return None, 0
    with open(p, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        start = max(0, size - TAIL_BYTES)
        f.seek(start)
        data = f.read()
    if start > 0:  # the block's first piece may be the end of a longer line: dropped
        cut = data.find(b"\n")
        data = data[cut + 1:] if cut >= 0 else b""
    lines = _last_lines(data)
    seq = _next_seq(lines)
    if lines and (seq is not None or start == 0):
        return hashlib.sha256(lines[0]).hexdigest(), seq or 0
    return _scan(p) if start > 0 else (None, 0)


def _scan(path: Path) -> tuple[str | None, int]:
    """:func:`log_tail` by reading the whole log in pieces of at most 1 MiB (a line is never held whole past
    :data:`MAX_RECORD_BYTES`)."""
    last, seq = None, 0
    digest, kept, blank = hashlib.sha256(), b"", True
    with open(path, "rb") as f:
        while piece := f.readline(1 << 20):
            digest.update(piece)
            blank = blank and not piece.strip()
            kept = kept + piece if len(kept) + len(piece) <= MAX_RECORD_BYTES else b"\0"
            if not piece.endswith(b"\n"):
                continue
            if not blank:
                last = digest.hexdigest()
                found = _next_seq([kept])
                seq = found if found is not None else seq
            digest, kept, blank = hashlib.sha256(), b"", True
    if not blank:  # a last line without its newline
        last = digest.hexdigest()
    return last, seq


def _weights_sha256(segmenter: Any) -> str | None:
    value = getattr(segmenter, "weights_sha256", None)
    return value if isinstance(value, str) and value else None


def flightlog_schema() -> dict[str, Any]:
    """The JSON Schema of a flight-log record (``el/data/flightlog.schema.json``)."""
    text = resources.files("el").joinpath("data/flightlog.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


__all__ = ["FORMAT", "MAX_LOGGED_CANDIDATES", "MAX_RECORD_BYTES", "FlightLog", "domain_verdict", "flight_record",
           "flightlog_schema", "log_tail", "record_line"]
