"""Safety requirements: the registry, the three verification states, and the campaign checks.

docs/architecture.md section 4.6. The registry (``assurance/requirements.yaml``) lists every requirement with its
id, title, text, source, rationale, verification method, acceptance criterion and operating domain;
``load_registry`` validates it (unique ids, required fields, known sources) and raises
``RegistryError`` naming the file and the entry.

A requirement ends a test session in one of three states (``requirement_state``):

- **verified**: at least one test claims it and every claiming test passed;
- **failed**: a claiming test failed (or errored, or is marked as an expected failure);
- **not verified**: no test claims it, or a claiming test was skipped (no campaign run, too little
  data to decide), deselected or not run.

The campaign checks (``check_*``) read a campaign run's readouts and results table and return an
``Evidence`` record: ``pass``, ``fail`` or ``insufficient`` (too little data to decide). The campaign
requirement tests (``tests/requirements``) turn ``insufficient`` into a skip (so the requirement is
"not verified", never "failed"); the evidence report shows the same records as supporting detail.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

__all__ = [
    "FAILED",
    "NOT_VERIFIED",
    "RESULTS_FORMAT",
    "STATES",
    "TIMING_COLUMNS",
    "VERIFIED",
    "Evidence",
    "Registry",
    "RegistryError",
    "Requirement",
    "TestOutcome",
    "check_artefacts_identified",
    "check_decision_time",
    "check_monitor_coverage",
    "check_perturbation_coverage",
    "check_pose_margin",
    "check_rerun",
    "check_safety_gain",
    "check_table_recomputation",
    "check_unsafe_landing_bound",
    "default_registry_path",
    "evaluate",
    "images_needed",
    "load_registry",
    "load_results",
    "requirement_state",
    "results_document",
]

VERIFIED, FAILED, NOT_VERIFIED = "verified", "failed", "not verified"
STATES: tuple[str, ...] = (VERIFIED, FAILED, NOT_VERIFIED)
REGISTRY_FORMAT = "uav-el-requirements/1"
RESULTS_FORMAT = "uav-el-requirement-results/1"
KNOWN_SOURCES: tuple[str, ...] = ("SORA", "SSIV21", "ICRA22", "PROJECT")
"""The only sources a requirement may cite (docs/architecture.md section 4.6: never invent a citation)."""

_ID = re.compile(r"^EL-R\d{2,3}$")
_FIELDS: tuple[str, ...] = ("id", "title", "text", "source", "rationale", "verification", "acceptance", "domain")
_PARAMETERS: dict[str, type | tuple[type, ...]] = {
    "deployed_monitor": str,
    "required_perturbations": list,
    "min_images_per_perturbation": int,
    "unsafe_landing_bound": (int, float),
    "confidence": (int, float),
    "time_budget_s": (int, float),
    "pose_error": dict,
    "rerun_shards": int,
}
TIMING_COLUMNS: frozenset[str] = frozenset({
    "read_s", "perturb_s", "segmentation_s", "candidates_s", "monitoring_s", "total_s", "overhead_s", "seconds",
    "overhead_s_lo95", "overhead_s_hi95",
})
"""Readout and table columns that may differ between two runs of the same campaign (docs/architecture.md 4.2)."""


# ------------------------------------------------------------------------------------------------
# The registry
# ------------------------------------------------------------------------------------------------
class RegistryError(ValueError):
    """The requirement registry is missing, malformed or inconsistent; the message names file and entry."""


@dataclass(frozen=True)
class Requirement:
    """One safety requirement of the registry."""

    id: str
    title: str
    text: str
    source: tuple[str, ...]
    rationale: str
    verification_method: str
    verification_kind: tuple[str, ...]
    acceptance: str
    domain: str


@dataclass(frozen=True)
class Registry:
    """The validated registry: requirements in file order, the parameters of their acceptance criteria."""

    path: Path
    sha256: str
    sources: dict[str, str]
    parameters: dict[str, Any]
    operating_domain: dict[str, str]
    requirements: dict[str, Requirement]

    def __contains__(self, req_id: object) -> bool:
        return req_id in self.requirements

    def __iter__(self):
        return iter(self.requirements.values())

    def __len__(self) -> int:
        return len(self.requirements)

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(self.requirements)

    def __getitem__(self, req_id: str) -> Requirement:
        return self.requirements[req_id]


def default_registry_path() -> Path:
    """The shipped registry, ``assurance/requirements.yaml``."""
    return Path(str(resources.files("assurance").joinpath("requirements.yaml")))


def _text(where: str, entry: Mapping[str, Any], name: str) -> str:
    value = entry.get(name)
    if not isinstance(value, str) or not value.strip():
        raise RegistryError(f"{where}: field '{name}' must be a non-empty string, got {value!r}")
    return " ".join(value.split())


def _requirement(where: str, entry: Any, sources: Mapping[str, str]) -> Requirement:
    if not isinstance(entry, dict):
        raise RegistryError(f"{where}: a requirement must be a mapping, got {type(entry).__name__}")
    missing = [f for f in _FIELDS if f not in entry]
    if missing:
        raise RegistryError(f"{where}: missing field(s) {', '.join(repr(m) for m in missing)}")
    unknown = sorted(set(entry) - set(_FIELDS))
    if unknown:
        raise RegistryError(f"{where}: unknown field(s) {', '.join(repr(u) for u in unknown)}")
    src = entry["source"]
    if isinstance(src, str):
        src = [src]
    if not isinstance(src, list) or not src or not all(isinstance(s, str) for s in src):
        raise RegistryError(f"{where}: 'source' must be a non-empty list of source keys, got {src!r}")
    bad = [s for s in src if s not in sources]
    if bad:
        raise RegistryError(f"{where}: unknown source(s) {bad}; cite only {', '.join(sources)}")
    ver = entry["verification"]
    if not isinstance(ver, dict) or "method" not in ver:
        raise RegistryError(f"{where}: 'verification' must be a mapping with a 'method'")
    kind = ver.get("kind", [])
    if not isinstance(kind, list) or not all(isinstance(k, str) for k in kind):
        raise RegistryError(f"{where}: 'verification.kind' must be a list of strings, got {kind!r}")
    return Requirement(
        id=entry["id"], title=_text(where, entry, "title"), text=_text(where, entry, "text"),
        source=tuple(src), rationale=_text(where, entry, "rationale"),
        verification_method=_text(where, ver, "method"), verification_kind=tuple(kind),
        acceptance=_text(where, entry, "acceptance"), domain=_text(where, entry, "domain"),
    )


def load_registry(path: str | Path | None = None) -> Registry:
    """Read and validate a requirement registry (default: the shipped one).

    Raises RegistryError for a missing or unparsable file, a wrong format tag, a requirement without
    one of the required fields, a malformed or duplicate id, an unknown source, or a missing parameter.
    """
    path = Path(path) if path is not None else default_registry_path()
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RegistryError(f"{path}: cannot read the requirement registry ({exc.strerror or exc})") from None
    try:
        doc = yaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise RegistryError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(doc, dict):
        raise RegistryError(f"{path}: the registry must be a YAML mapping")
    if doc.get("format") != REGISTRY_FORMAT:
        raise RegistryError(f"{path}: format must be {REGISTRY_FORMAT!r}, got {doc.get('format')!r}")
    sources = doc.get("sources")
    if not isinstance(sources, dict) or not sources:
        raise RegistryError(f"{path}: 'sources' must be a non-empty mapping")
    invented = sorted(set(sources) - set(KNOWN_SOURCES))
    if invented:
        raise RegistryError(f"{path}: sources {invented} are not allowed; cite only {', '.join(KNOWN_SOURCES)}")
    params = doc.get("parameters")
    if not isinstance(params, dict):
        raise RegistryError(f"{path}: 'parameters' must be a mapping")
    for name, typ in _PARAMETERS.items():
        if name not in params:
            raise RegistryError(f"{path}: parameters: missing {name!r}")
        if isinstance(params[name], bool) or not isinstance(params[name], typ):
            raise RegistryError(f"{path}: parameters.{name} has the wrong type ({params[name]!r})")
    if not 0 < params["unsafe_landing_bound"] < 1 or not 0 < params["confidence"] < 1:
        raise RegistryError(f"{path}: parameters.unsafe_landing_bound and confidence must lie in (0, 1)")
    if params["min_images_per_perturbation"] < 1 or params["rerun_shards"] < 0 or params["time_budget_s"] <= 0:
        raise RegistryError(f"{path}: parameters: min_images_per_perturbation >= 1, rerun_shards >= 0, "
                            "time_budget_s > 0")
    domain = doc.get("operating_domain")
    if not isinstance(domain, dict) or not all(isinstance(v, str) for v in domain.values()):
        raise RegistryError(f"{path}: 'operating_domain' must be a mapping of strings")
    entries = doc.get("requirements")
    if not isinstance(entries, list) or not entries:
        raise RegistryError(f"{path}: 'requirements' must be a non-empty list")
    reqs: dict[str, Requirement] = {}
    for i, entry in enumerate(entries):
        rid = entry.get("id") if isinstance(entry, dict) else None
        where = f"{path}: requirements[{i}]" + (f" ({rid})" if isinstance(rid, str) else "")
        if not isinstance(rid, str) or not _ID.match(rid):
            raise RegistryError(f"{where}: 'id' must look like 'EL-R01', got {rid!r}")
        if rid in reqs:
            raise RegistryError(f"{where}: duplicate id {rid!r}")
        reqs[rid] = _requirement(where, entry, sources)
    return Registry(path=path, sha256=hashlib.sha256(raw).hexdigest(), sources=dict(sources),
                    parameters=dict(params), operating_domain={k: " ".join(v.split()) for k, v in domain.items()},
                    requirements=reqs)


# ------------------------------------------------------------------------------------------------
# Test outcomes -> requirement states
# ------------------------------------------------------------------------------------------------
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
        "registry": {"path": str(registry.path), "sha256": registry.sha256},
        "context": dict(context or {}),
        "exitstatus": exitstatus,
        "collection_errors": list(collection_errors),
        "summary": summary_counts(r.state for r in results.values()),
        "requirements": {rid: r.to_dict() for rid, r in results.items()},
    }


def load_results(path: str | Path, registry: Registry) -> tuple[dict[str, RequirementResult], dict[str, Any]]:
    """Read a results JSON written by the plugin (or an ``evidence.json``, which carries the same states);
    returns (results for every registry id, the document).

    Requirements of the registry absent from the file are "not verified" ("not in the test results");
    ids in the file that the registry lacks are ignored (listed in ``doc['ignored_ids']``).
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: requirement results not found (run: pytest -m requirements)") from None
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


# ------------------------------------------------------------------------------------------------
# Campaign evidence
# ------------------------------------------------------------------------------------------------
PASS, FAIL, INSUFFICIENT = "pass", "fail", "insufficient"


@dataclass(frozen=True)
class Evidence:
    """What a campaign check found: ``status`` pass / fail / insufficient, a one-line summary, details.

    ``rows`` are records (dicts of plain values) for the report's tables; ``columns`` names their keys
    in display order.
    """

    requirement: str
    name: str
    status: str
    summary: str
    rows: tuple[dict[str, Any], ...] = ()
    columns: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.status not in (PASS, FAIL, INSUFFICIENT):
            raise ValueError(f"status must be pass, fail or insufficient, got {self.status!r}")

    def message(self, limit: int = 10) -> str:
        """The summary, with the first ``limit`` detail rows (for a test's failure message)."""
        lines = [self.summary]
        for row in self.rows[:limit]:
            lines.append("  " + ", ".join(f"{k}={row.get(k)}" for k in (self.columns or row)))
        if len(self.rows) > limit:
            lines.append(f"  ... {len(self.rows) - limit} more")
        return "\n".join(lines)


def _ok_images(images: Any) -> Any:
    if images is None or len(images) == 0:
        return images
    return images[images["fault"].fillna("") == ""]


def check_monitor_coverage(images: Any, candidates: Any) -> Evidence:
    """EL-R04 on campaign readouts: every 'land' decision is on an accepted candidate, every candidate
    ranked before it was rejected, and the two readout tables agree on the decision.

    ``images`` / ``candidates``: the run's tables (``assurance.readouts.load_table``).
    """
    rid, name = "EL-R04", "monitor coverage of every decision"
    ok = _ok_images(images)
    if ok is None or len(ok) == 0:
        return Evidence(rid, name, INSUFFICIENT, "no evaluated image in the readouts")
    groups: dict[tuple, Any] = {}
    if candidates is not None and len(candidates):
        for key, g in candidates.groupby(["perturbation", "severity", "monitor", "key"], sort=False):
            groups[key] = g.sort_values("rank")
    violations: list[dict[str, Any]] = []
    lands = 0
    for row in ok.itertuples(index=False):
        key = (row.perturbation, row.severity, row.monitor, row.key)
        g = groups.get(key)
        n = 0 if g is None else len(g)
        accepted = np.zeros(0, bool) if g is None else g["accepted"].to_numpy(bool)
        flagged = np.zeros(0, bool) if g is None else g["selected"].to_numpy(bool)
        ranks = np.zeros(0, int) if g is None else g["rank"].to_numpy(int)
        sel = int(row.selected)
        problem = ""
        if int(row.candidates) != n:
            problem = f"images table says {int(row.candidates)} candidates, candidates table has {n}"
        elif row.action == "land":
            lands += 1
            if not 0 <= sel < n:
                problem = f"landed on candidate {sel}, which does not exist"
            elif not accepted[sel]:
                problem = f"landed on candidate {sel}, which the monitor rejected"
            elif accepted[:sel].any():
                first = int(np.flatnonzero(accepted[:sel])[0])
                problem = f"landed on candidate {sel} although candidate {first}, ranked before, was accepted"
            elif not np.array_equal(flagged, ranks == sel):
                problem = "candidates table disagrees with the images table on the selected candidate"
        else:
            if flagged.any():
                problem = "default action but a candidate is flagged as selected"
            elif accepted.any():
                problem = f"default action although candidate {int(np.flatnonzero(accepted)[0])} was accepted"
        if problem:
            violations.append({"perturbation": row.perturbation, "severity": int(row.severity),
                               "monitor": row.monitor, "image": row.key, "action": row.action, "problem": problem})
    cols = ("perturbation", "severity", "monitor", "image", "action", "problem")
    if violations:
        return Evidence(rid, name, FAIL, f"{len(violations)} decision(s) of {len(ok)} break monitor coverage "
                        f"({lands} landings)", tuple(violations), cols)
    return Evidence(rid, name, PASS, f"all {lands} landing(s) of {len(ok)} decisions are on a monitor-accepted "
                    "candidate with every candidate ranked before rejected", (), cols)


def check_perturbation_coverage(images: Any, required: Sequence[str], min_images: int) -> Evidence:
    """EL-R08 on campaign readouts: each required perturbation has >= ``min_images`` non-faulted images.

    A missing perturbation or too few images is insufficient evidence (not a failure of the system).
    """
    rid, name = "EL-R08", "perturbation coverage"
    ok = _ok_images(images)
    rows = []
    for p in required:
        if ok is None or len(ok) == 0:
            n, sev = 0, ""
        else:
            sub = ok[ok["perturbation"] == p]
            n = int(sub["key"].nunique())
            sev = ", ".join(str(int(s)) for s in sorted(sub["severity"].unique()))
        faults = 0 if images is None or len(images) == 0 else int(
            ((images["perturbation"] == p) & (images["fault"].fillna("") != "")).sum())
        rows.append({"perturbation": p, "severities": sev or "-", "images": n, "faulted": faults,
                     "enough": n >= min_images})
    cols = ("perturbation", "severities", "images", "faulted", "enough")
    short = [r["perturbation"] for r in rows if not r["enough"]]
    if short:
        return Evidence(rid, name, INSUFFICIENT, f"insufficient evidence: {', '.join(short)} missing or with fewer "
                        f"than {min_images} evaluated images", tuple(rows), cols)
    return Evidence(rid, name, PASS, f"all {len(required)} perturbations evaluated with >= {min_images} images each",
                    tuple(rows), cols)


def _deployed_rows(table: Any, monitor: str) -> Any:
    if table is None or len(table) == 0:
        return table
    return table[table["monitor"] == monitor]


def _finite(v: Any) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def check_safety_gain(table: Any, monitor: str, required: Sequence[str], min_images: int) -> Evidence:
    """EL-R09: G* 95% lower bound > 0 for ``monitor`` in every evaluated scenario.

    Insufficient when the monitor was not evaluated, a required perturbation is missing or has fewer
    than ``min_images`` images, or a lower bound is undefined.
    """
    rid, name = "EL-R09", f"safety gain G* of the deployed monitor ({monitor})"
    rows_df = _deployed_rows(table, monitor)
    cols = ("perturbation", "severity", "images", "g_star", "g_star_lo95", "g_star_hi95", "verdict")
    if rows_df is None or len(rows_df) == 0:
        return Evidence(rid, name, INSUFFICIENT, f"insufficient evidence: monitor {monitor!r} was not evaluated")
    rows, fails, short = [], [], []
    for r in rows_df.itertuples(index=False):
        lo = r.g_star_lo95
        if int(r.images) < min_images or not _finite(lo):
            verdict = "insufficient"
            short.append(f"{r.perturbation} (s{int(r.severity)})")
        elif float(lo) > 0:
            verdict = "pass"
        else:
            verdict = "fail"
            fails.append(f"{r.perturbation} (s{int(r.severity)})")
        rows.append({"perturbation": r.perturbation, "severity": int(r.severity), "images": int(r.images),
                     "g_star": _num(r.g_star), "g_star_lo95": _num(lo), "g_star_hi95": _num(r.g_star_hi95),
                     "verdict": verdict})
    missing = [p for p in required if p not in set(rows_df["perturbation"])]
    if fails:
        return Evidence(rid, name, FAIL, f"G* 95% lower bound <= 0 under {', '.join(fails)}", tuple(rows), cols)
    if missing or short:
        what = [f"{p} not evaluated" for p in missing] + [f"{s} has too few images or no interval" for s in short]
        return Evidence(rid, name, INSUFFICIENT, "insufficient evidence: " + "; ".join(what), tuple(rows), cols)
    return Evidence(rid, name, PASS, f"G* 95% lower bound > 0 in all {len(rows)} scenario(s)", tuple(rows), cols)


def images_needed(bound: float, conf: float = 0.95) -> int:
    """The fewest images for which zero unsafe landings give a one-sided upper bound <= ``bound``.

    >>> images_needed(0.05)
    59
    """
    if not 0 < bound < 1:
        raise ValueError(f"bound must lie in (0, 1), got {bound!r}")
    # Clopper-Pearson with k = 0: ub = 1 - (1 - conf) ** (1 / n)  <=  bound
    return int(math.ceil(math.log(1.0 - conf) / math.log(1.0 - bound) - 1e-12))


def check_unsafe_landing_bound(table: Any, monitor: str, bound: float, required: Sequence[str],
                               conf: float = 0.95) -> Evidence:
    """EL-R10: the unsafe-landing rate's one-sided upper bound <= ``bound`` for ``monitor``, per scenario.

    A scenario whose bound exceeds ``bound`` fails when the sample was large enough for zero unsafe
    landings to meet it; otherwise the sample is too small to decide (insufficient).
    """
    from assurance.metrics import clopper_pearson_upper

    rid, name = "EL-R10", f"unsafe-landing rate of the deployed monitor ({monitor}), bound {bound:g}"
    rows_df = _deployed_rows(table, monitor)
    cols = ("perturbation", "severity", "images", "unsafe_landings", "unsafe_landing_rate", "unsafe_landing_ub95",
            "verdict")
    if rows_df is None or len(rows_df) == 0:
        return Evidence(rid, name, INSUFFICIENT, f"insufficient evidence: monitor {monitor!r} was not evaluated")
    need = images_needed(bound, conf)
    rows, fails, short = [], [], []
    for r in rows_df.itertuples(index=False):
        n = int(r.images)
        k = int(round(float(r.unsafe_landing_rate) * n)) if n and _finite(r.unsafe_landing_rate) else 0
        ub = float(r.unsafe_landing_ub95) if _finite(r.unsafe_landing_ub95) else math.nan
        scen = f"{r.perturbation} (s{int(r.severity)})"
        if n == 0 or not math.isfinite(ub):
            verdict = "insufficient"
            short.append(scen)
        elif ub <= bound:
            verdict = "pass"
        elif clopper_pearson_upper(0, n, conf) > bound:
            verdict = "insufficient"
            short.append(scen)
        else:
            verdict = "fail"
            fails.append(scen)
        rows.append({"perturbation": r.perturbation, "severity": int(r.severity), "images": n,
                     "unsafe_landings": k, "unsafe_landing_rate": _num(r.unsafe_landing_rate),
                     "unsafe_landing_ub95": _num(ub), "verdict": verdict})
    missing = [p for p in required if p not in set(rows_df["perturbation"])]
    if fails:
        return Evidence(rid, name, FAIL, f"upper bound > {bound:g} under {', '.join(fails)}", tuple(rows), cols)
    if missing or short:
        what = [f"{p} not evaluated" for p in missing]
        if short:
            what.append(f"{', '.join(short)}: too few images to show {bound:g} (needs >= {need} images with no "
                        "unsafe landing)")
        return Evidence(rid, name, INSUFFICIENT, "insufficient evidence: " + "; ".join(what), tuple(rows), cols)
    return Evidence(rid, name, PASS, f"upper bound <= {bound:g} in all {len(rows)} scenario(s)", tuple(rows), cols)


def check_decision_time(images: Any, monitor: str, budget_s: float) -> Evidence:
    """EL-R13: every image's decision time with ``monitor`` (segmentation + candidates + the walk's
    monitoring overhead) is within ``budget_s`` on the campaign's machine."""
    rid, name = "EL-R13", f"decision time of the deployed monitor ({monitor}) within {budget_s:g} s"
    ok = _ok_images(images)
    cols = ("perturbation", "severity", "images", "mean_s", "p95_s", "max_s", "over_budget")
    if ok is None or len(ok) == 0 or not (ok["monitor"] == monitor).any():
        return Evidence(rid, name, INSUFFICIENT, f"insufficient evidence: monitor {monitor!r} was not evaluated")
    sub = ok[ok["monitor"] == monitor]
    t = (sub["segmentation_s"].astype(float) + sub["candidates_s"].astype(float) + sub["overhead_s"].astype(float))
    sub = sub.assign(decision_s=t)
    rows = []
    for (p, s), g in sub.groupby(["perturbation", "severity"], sort=False):
        d = g["decision_s"].to_numpy(float)
        rows.append({"perturbation": p, "severity": int(s), "images": len(d), "mean_s": _num(d.mean()),
                     "p95_s": _num(np.percentile(d, 95)), "max_s": _num(d.max()),
                     "over_budget": int((d > budget_s).sum())})
    over = int((t > budget_s).sum())
    if over:
        return Evidence(rid, name, FAIL, f"{over} of {len(t)} decisions took longer than {budget_s:g} s "
                        f"(max {t.max():.2f} s)", tuple(rows), cols)
    return Evidence(rid, name, PASS, f"all {len(t)} decisions within {budget_s:g} s (max {t.max():.2f} s)",
                    tuple(rows), cols)


def check_pose_margin(core: Mapping[str, Any], size: tuple[int, int], pose_error: Mapping[str, float]) -> Evidence:
    """EL-R14: beta >= the beta required for the pose-error box, at working resolution.

    ``core``: a CoreConfig or its dict (``CoreConfig.to_dict``); ``size``: the input image (W, H).
    """
    from el.camera import CameraGeometry, required_beta, working_size
    from el.config import CoreConfig

    cfg = core if isinstance(core, CoreConfig) else CoreConfig.from_dict(dict(core))
    w, h = working_size(int(size[0]), int(size[1]), cfg.working_width)
    geo = CameraGeometry(width=w, height=h, intrinsics=cfg.intrinsics, pose=cfg.pose)
    he, pe = float(pose_error["height"]), float(pose_error["pitch"])
    need = required_beta(geo, height_error=he, pitch_error=pe)
    beta = float(cfg.safety.beta)
    row = {"working_size": f"{w}x{h}", "height_m": cfg.pose.height_m, "pitch_deg": cfg.pose.pitch_deg,
           "height_error": he, "pitch_error": pe, "beta": beta, "required_beta": round(need, 4)}
    cols = tuple(row)
    rel = ">=" if beta >= need else "<"
    verdict = f"beta {beta:g} {rel} required {need:.3f} for +-{he:.0%} height, +-{pe:.0%} pitch"
    return Evidence("EL-R14", "pose-error margin of beta", PASS if beta >= need else FAIL, verdict, (row,), cols)


def _sha(v: Any) -> bool:
    return isinstance(v, str) and re.fullmatch(r"[0-9a-f]{64}", v) is not None


def check_artefacts_identified(manifest: Mapping[str, Any]) -> Evidence:
    """EL-R12 on a run: its manifest identifies weights and data by SHA-256, and the code by version and commit."""
    rows = [
        {"artefact": "weights", "identity": (manifest.get("weights") or {}).get("sha256")},
        {"artefact": "data", "identity": (manifest.get("data") or {}).get("sha256")},
        {"artefact": "configuration", "identity": config_sha256(manifest.get("config") or {})
         if manifest.get("config") else None},
        {"artefact": "code", "identity": (manifest.get("code") or {}).get("git_commit")},
    ]
    bad = [r["artefact"] for r in rows[:3] if not _sha(r["identity"])]
    if not rows[3]["identity"]:
        bad.append("code (no git commit recorded)")
    cols = ("artefact", "identity")
    if bad:
        return Evidence("EL-R12", "artefacts identified by the run manifest", FAIL,
                        f"the run manifest does not identify: {', '.join(bad)}", tuple(rows), cols)
    return Evidence("EL-R12", "artefacts identified by the run manifest", PASS,
                    "weights, data and configuration identified by SHA-256, code by git commit", tuple(rows), cols)


def config_sha256(config: Mapping[str, Any]) -> str:
    """SHA-256 of a configuration as canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def check_table_recomputation(run: str | Path, *, n_boot: int = 500) -> Evidence:
    """EL-R11: the results table recomputed from the readouts is the same whatever the order in which
    the shards are read, and equals the run's stored ``results.csv`` (if any), timing columns aside."""
    import pandas as pd

    from assurance import readouts
    from assurance.metrics import ScenarioMetrics, rows_to_frame
    from assurance.table import image_readouts, results_table

    run = Path(run)
    name = "results table recomputed from the readouts"
    table = results_table(run, n_boot=n_boot)
    images = readouts.load_table(run, "images")
    cands = readouts.load_table(run, "candidates")
    rng = np.random.default_rng(12345)
    shuffled = image_readouts(images.iloc[rng.permutation(len(images))],
                              cands.iloc[rng.permutation(len(cands))] if len(cands) else cands)
    rows = []
    for r in table.itertuples(index=False):
        sm = ScenarioMetrics(r.perturbation, int(r.severity), r.monitor, n_boot=n_boot, seed=0)
        sm.extend(shuffled.get((r.perturbation, int(r.severity), r.monitor), []))
        rows.append(sm.compute())
    again = rows_to_frame(rows)
    cols = [c for c in again.columns if c not in TIMING_COLUMNS]
    problems = []
    if not table[cols].reset_index(drop=True).equals(again[cols]):
        diff = [c for c in cols if not table[c].reset_index(drop=True).equals(again[c])]
        problems.append({"what": "shuffled readouts", "columns": ", ".join(diff)})
    stored = run / "results.csv"
    if stored.is_file():
        full = results_table(run)  # the stored table used the default resamples
        old = pd.read_csv(stored)
        num = [c for c in cols if c in old.columns and c not in ("perturbation", "monitor")]
        if len(old) != len(full) or list(old["monitor"]) != list(full["monitor"]):
            problems.append({"what": "results.csv", "columns": "rows differ"})
        else:
            a, b = old[num].to_numpy(float), full[num].to_numpy(float)
            close = np.isclose(a, b, rtol=1e-5, atol=1e-9, equal_nan=True)  # CSV keeps 6 significant digits
            if not close.all():
                bad = sorted({num[j] for j in np.flatnonzero(~close.all(axis=0))})
                problems.append({"what": "results.csv", "columns": ", ".join(bad)})
    if problems:
        return Evidence("EL-R11", name, FAIL, "the results table is not reproducible from the readouts",
                        tuple(problems), ("what", "columns"))
    extra = " and equals results.csv" if stored.is_file() else " (no results.csv stored to compare with)"
    return Evidence("EL-R11", name, PASS, f"{len(table)} rows identical whatever the shard order{extra}")


def check_rerun(run: str | Path, *, shards: int = 1, work_dir: str | Path, threads: int | None = None,
                segmenter: Any = None) -> Evidence:
    """EL-R11: re-run ``shards`` tasks of a campaign from scratch and compare their readouts with the stored
    ones (timings aside). Insufficient when the data or weights are gone or changed since the run.

    The tasks re-run are the first ones (sorted shard names) of a randomised perturbation, so the
    per-image seeding is exercised too. ``segmenter`` replaces the model of the manifest's weights.
    """
    import pandas as pd

    from assurance import readouts
    from assurance.campaign import CampaignConfig, execute, plan
    from el.config import CoreConfig

    name = "re-run of campaign shards"
    run = Path(run)
    man = readouts.read_manifest(run)
    cfg_d = dict(man["config"])
    cfg_d["core"] = CoreConfig.from_dict(cfg_d["core"])
    for k in ("perturbations", "severities", "monitors"):
        cfg_d[k] = tuple(cfg_d[k])
    config = CampaignConfig(**cfg_d)
    data = Path(man["data"]["path"])
    if not data.is_dir():
        return Evidence("EL-R11", name, INSUFFICIENT, f"insufficient evidence: the run's data folder {data} is gone")
    weights = (man.get("weights") or {}).get("path")
    if segmenter is None:
        from el.segmentation.weights import sha256_file

        if not weights or not Path(weights).is_file():
            return Evidence("EL-R11", name, INSUFFICIENT,
                            f"insufficient evidence: the run's weights {weights} are gone")
        if sha256_file(weights) != man["weights"].get("sha256"):
            return Evidence("EL-R11", name, INSUFFICIENT,
                            f"insufficient evidence: the weights file {weights} changed since the run")
    from assurance.campaign import manifest as make_manifest

    try:
        planned = plan(data, config)
        data_sha = make_manifest(data, config, planned)["data"]["sha256"]
    except Exception as exc:  # the data folder no longer reads as the campaign's data set
        return Evidence("EL-R11", name, INSUFFICIENT, f"insufficient evidence: cannot re-plan the run on {data}: {exc}")
    if data_sha != man["data"]["sha256"]:
        return Evidence("EL-R11", name, INSUFFICIENT,
                        f"insufficient evidence: the data in {data} changed since the run")
    tasks = {t.shard_name: t for t in planned}
    done = sorted(n for n in tasks if readouts.shard_done(run, n))
    if not done:
        return Evidence("EL-R11", name, INSUFFICIENT, "insufficient evidence: no finished shard to re-run")
    randomised = [n for n in done if tasks[n].perturbation not in ("none", "brightness")]
    pick = (randomised or done)[:max(1, shards)]
    work = Path(work_dir)
    (work / readouts.SHARDS).mkdir(parents=True, exist_ok=True)
    rows = []
    threads = threads or man.get("threads_per_worker") or os.cpu_count() or 1
    for shard in pick:  # the campaign's own thread count: float sums depend on it
        execute(tasks[shard], config, str(work), threads, segmenter)
        for table in readouts.TABLES:
            a = pd.read_parquet(run / readouts.SHARDS / shard / f"{table}.parquet")
            b = pd.read_parquet(work / readouts.SHARDS / shard / f"{table}.parquet")
            cols = [c for c in a.columns if c not in TIMING_COLUMNS and c != "traceback"]
            diff = []
            if list(a.columns) != list(b.columns):
                diff = ["(the columns differ)"]
            elif len(a) != len(b):
                diff = [f"(rows: {len(a)} stored, {len(b)} re-run)"]
            else:
                for c in cols:
                    x, y = a[c].to_numpy(), b[c].to_numpy()
                    if x.dtype.kind == "f":
                        if not np.array_equal(x, y, equal_nan=True):
                            diff.append(c)
                    elif not (x == y).all():
                        diff.append(c)
            rows.append({"shard": shard, "table": table, "rows": len(a), "differing_columns": ", ".join(diff) or "-"})
    cols = ("shard", "table", "rows", "differing_columns")
    bad = [r for r in rows if r["differing_columns"] != "-"]
    if bad:
        return Evidence("EL-R11", name, FAIL, f"re-running {len(pick)} shard(s) changed the readouts",
                        tuple(rows), cols)
    return Evidence("EL-R11", name, PASS, f"re-running {len(pick)} shard(s) gave identical readouts (timings aside)",
                    tuple(rows), cols)


def _num(v: Any) -> float | None:
    """A plain float for records (None for NaN, so JSON stays valid)."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None
