"""Test outcomes -> requirement states, and the results document the pytest plugin writes (section 4.6).

A requirement ends a test session in one of three states (``requirement_state``):

- **verified**: at least one test claims it and every claiming test passed;
- **failed**: a claiming test failed (or errored, or is marked as an expected failure);
- **not verified**: no test claims it, or a claiming test was skipped (no campaign run, too little
  data to decide), deselected or not run.

A rate bound is decided at any sample size (``assurance.analysis.intervals.decide_rate_bound``): its check fails
when the one-sided lower bound already exceeds the target, so "too little data" means the bounds straddle it.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from assurance.requirements.registry import Registry
from el.base import userfiles

VERIFIED, FAILED, NOT_VERIFIED = "verified", "failed", "not verified"
STATES: tuple[str, ...] = (VERIFIED, FAILED, NOT_VERIFIED)
RESULTS_FORMAT = "uav-el-requirement-results/1"
PASSING = frozenset({"passed", "xpassed"})
FAILING = frozenset({"failed", "error", "xfailed"})
OUTCOMES = ("passed", "xpassed", "failed", "error", "xfailed", "skipped", "deselected", "not run")


@dataclass(frozen=True)
class TestOutcome:
    """The outcome of one test that claims requirements."""

    __test__ = False  # not a pytest test class

    nodeid: str
    outcome: str
    duration: float = 0.0
    message: str = ""

    def __post_init__(self) -> None:
        if self.outcome not in OUTCOMES:
            raise ValueError(f"outcome must be one of {OUTCOMES}, got {self.outcome!r}")

    def to_dict(self) -> dict[str, Any]:
        return {"nodeid": self.nodeid, "outcome": self.outcome, "duration": round(float(self.duration), 6),
                "message": self.message}


def requirement_state(tests: Sequence[TestOutcome]) -> tuple[str, str]:
    """The state of one requirement from the outcomes of the tests that claim it, with a reason.

    >>> requirement_state([TestOutcome("t::a", "passed"), TestOutcome("t::b", "skipped", message="no run")])
    ('not verified', '1 of 2 claiming test(s) skipped: t::b (no run)')
    >>> requirement_state([])
    ('not verified', 'no test claims it')
    """
    if not tests:
        return NOT_VERIFIED, "no test claims it"
    failing = [t for t in tests if t.outcome in FAILING]
    if failing:
        first = failing[0]
        why = f": {first.message}" if first.message else ""
        return FAILED, f"{len(failing)} of {len(tests)} claiming test(s) failed: {first.nodeid}{why}"
    open_ = [t for t in tests if t.outcome not in PASSING]
    if open_:
        first = open_[0]
        verb = {"skipped": "skipped", "deselected": "deselected", "not run": "not run"}[first.outcome]
        why = f" ({first.message})" if first.message else ""
        return NOT_VERIFIED, f"{len(open_)} of {len(tests)} claiming test(s) {verb}: {first.nodeid}{why}"
    return VERIFIED, f"all {len(tests)} claiming test(s) passed"


@dataclass
class RequirementResult:
    """A requirement's state after a test session."""

    id: str
    title: str
    state: str
    reason: str
    tests: list[TestOutcome] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "title": self.title, "state": self.state, "reason": self.reason,
                "tests": [t.to_dict() for t in self.tests]}


def evaluate(registry: Registry, outcomes: Iterable[tuple[Sequence[str], TestOutcome]]) -> dict[str, RequirementResult]:
    """Every registry requirement's state, from (claimed ids, outcome) pairs of the claiming tests."""
    per_id: dict[str, list[TestOutcome]] = {rid: [] for rid in registry.ids}
    for ids, outcome in outcomes:
        for rid in dict.fromkeys(ids):
            if rid in per_id:
                per_id[rid].append(outcome)
    out = {}
    for req in registry:
        tests = sorted(per_id[req.id], key=lambda t: t.nodeid)
        state, reason = requirement_state(tests)
        out[req.id] = RequirementResult(req.id, req.title, state, reason, tests)
    return out


def summary_counts(states: Iterable[str]) -> dict[str, int]:
    """How many requirements are in each state (every state listed, zeros included)."""
    counts = dict.fromkeys(STATES, 0)
    for s in states:
        counts[s] += 1
    return counts


def results_document(registry: Registry, results: Mapping[str, RequirementResult], *,
                     context: Mapping[str, Any] | None = None, collection_errors: Sequence[str] = (),
                     exitstatus: int | None = None) -> dict[str, Any]:
    """The JSON document the pytest plugin writes (``--requirements-report``)."""
    return {
        "format": RESULTS_FORMAT,
        "registry": {"path": str(registry.path), "sha256": registry.sha256, "targets": dict(registry.targets),
                     "targets_source": registry.targets_source, "parameters": dict(registry.parameters),
                     "parameters_sha256": registry.parameters_sha256},
        "context": dict(context or {}),
        "exitstatus": exitstatus,
        "collection_errors": list(collection_errors),
        "summary": summary_counts(r.state for r in results.values()),
        "requirements": {rid: r.to_dict() for rid, r in results.items()},
    }


MAX_RESULTS_BYTES = 64 << 20
"""A requirement results file (``requirements.json`` or an ``evidence.json``): a few hundred kB for the registry."""


def load_results(path: str | Path, registry: Registry) -> tuple[dict[str, RequirementResult], dict[str, Any]]:
    """Read a results JSON written by the plugin (or an ``evidence.json``, which carries the same states);
    returns (results for every registry id, the document).

    Requirements of the registry absent from the file are "not verified" ("not in the test results");
    ids in the file that the registry lacks are ignored (listed in ``doc['ignored_ids']``).
    """
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise FileNotFoundError(f"{path}: requirement results not found (run: uav-el verify RUN --out DIR)")
    try:  # bounded: a FIFO, a device, a link to /proc or a file over 64 MiB is refused unread
        doc = json.loads(userfiles.read_text(path, what="requirement results", max_bytes=MAX_RESULTS_BYTES))
    except userfiles.UserFileError as exc:
        raise ValueError(str(exc)) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: unreadable requirement results ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") not in (RESULTS_FORMAT, "uav-el-evidence/1"):
        raise ValueError(f"{path}: not a requirement results file (format must be {RESULTS_FORMAT!r}, "
                         "or an evidence.json)")
    given = doc.get("requirements") or {}
    out: dict[str, RequirementResult] = {}
    for req in registry:
        entry = given.get(req.id)
        if not isinstance(entry, dict):
            out[req.id] = RequirementResult(req.id, req.title, NOT_VERIFIED, "not in the test results")
            continue
        tests = [TestOutcome(str(t.get("nodeid", "")), str(t.get("outcome", "not run")),
                             float(t.get("duration") or 0.0), str(t.get("message") or ""))
                 for t in entry.get("tests", []) if isinstance(t, dict) and t.get("outcome") in OUTCOMES]
        state = entry.get("state")
        if state not in STATES:
            raise ValueError(f"{path}: {req.id}: unknown state {state!r}")
        out[req.id] = RequirementResult(req.id, req.title, state, str(entry.get("reason", "")), tests)
    doc = dict(doc)
    doc["ignored_ids"] = sorted(set(given) - set(registry.ids))
    return out, doc
