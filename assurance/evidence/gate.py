"""The evidence gate: are the requirement results bound to this run, what do waivers cover, what is the verdict.

FAILED (exit 1) when a requirement failed and is not waived, when one is not verified (a deselected,
skipped or uncollected test decides nothing) unless the registry declares it undecidable at this run
size (``size_limited``, on a run smaller than ``assurance.evidence.context.decisive_images``, and only when the run
size is what leaves it undecided: not a requirement no run size decides here, such as the calibration requirement
without a calibration card), or when there is an integrity problem
(results not signed or not bound to this run, code and registry; a state contradicting its own tests or
this report's check of the run; a waiver that is expired, of an unknown or non-failed requirement, by an
undeclared owner or too far ahead), or when the system deviates from the certification basis and the auditor did
not accept it (``assurance.requirements.basis``: a looser target or a hazardous class declared safe; counted apart
from the integrity problems); WAIVED (exit 0) when every failure is waived; INCOMPLETE when only
undecidable requirements are not verified (exit 1 with ``strict``, which also ignores waivers and fails
on a missing PDF); PASSED otherwise.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from assurance import requirements as rq
from assurance.campaign.integrity import RunCheck, code_sha256
from assurance.evidence.navigation import clean_message
from assurance.evidence.waivers import DEFAULT_MAX_WAIVER_DAYS, load_waivers, waiver_expired, waiver_problems
from assurance.requirements.weakening import registry_weakenings
from assurance.system import default_system

GATE_CLASS = {"FAILED": "failed", "WAIVED": "failed", "INCOMPLETE": "not-verified", "PASSED": "verified"}
DEVIATION = "deviation from the certification basis"
"""How a gate problem that is a deviation not accepted (``assurance.requirements.basis``) opens."""


@dataclass
class EvidenceReport:
    """What ``generate`` wrote and what the gate says."""

    out: Path
    html: Path
    json: Path
    pdf: Path | None
    pdf_error: str | None
    states: dict[str, str]
    exit_code: int
    warnings: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    waived: list[str] = field(default_factory=list)
    blocking: list[str] = field(default_factory=list)  # failed and not waived, or not verified and decidable

    def ids(self, state: str) -> list[str]:
        """The requirement ids in ``state``."""
        return [rid for rid, s in self.states.items() if s == state]

    def summary_lines(self) -> list[str]:
        """One line per state (with the ids of the failed and not-verified ones) and where the report is (why there
        is no PDF only when it was not asked for: a PDF that failed is among the warnings, for stderr)."""
        lines = []
        for state in rq.STATES:
            ids = self.ids(state)
            shown = [f"{i} (waived)" if i in self.waived else i for i in ids]
            tail = f"  {', '.join(shown)}" if ids and state != rq.VERIFIED else ""
            lines.append(f"{state + ':':<14}{len(ids):3d}{tail}")
        lines += [f"gate problem: {p}" for p in self.problems]
        files = [self.html] + ([self.pdf] if self.pdf else []) + [self.json]
        lines.append("report: " + ", ".join(str(f) for f in files))
        if self.pdf_error and self.pdf_error not in self.warnings:  # a PDF that could not be made: a warning
            lines.append(self.pdf_error)
        return lines


def requirement_results(registry: rq.Registry, path: Path | None, run: Path, warnings: list[str],
                         problems: list[str], check: RunCheck | None = None,
                         ) -> tuple[dict[str, rq.RequirementResult], dict[str, Any] | None]:
    """The requirement results of ``path`` and what they say about the gate.

    ``problems`` (each fails the gate) gets: results not bound to this run's digest, this code or this
    registry; a state that is not the one its own test outcomes give.
    """
    if path is None:
        warnings.append("no requirement test results were given: every requirement is 'not verified' "
                        f"(run: uav-el verify {run} --out <out>)")
        results = {r.id: rq.RequirementResult(r.id, r.title, rq.NOT_VERIFIED, "no test results given")
                   for r in registry}
        return results, None
    results, doc = rq.load_results(path, registry)
    ctx = doc.get("context") or {}
    if ctx.get("run") and Path(ctx["run"]).resolve() != run.resolve():
        warnings.append(f"the requirement results were produced on run {ctx['run']}, not on {run}")
    if check is not None:
        problems.extend(binding_problems(doc, check.digest, code_sha256(), registry.sha256, path,
                                         parameters_sha=registry.parameters_sha256))
    for rid, res in results.items():
        if not res.tests:
            if res.state != rq.NOT_VERIFIED:
                problems.append(f"{path}: {rid} is '{res.state}' with no test outcome behind it")
            continue
        own, _ = rq.requirement_state(res.tests)
        if own != res.state:
            problems.append(f"{path}: {rid} is '{res.state}' but its own test outcomes give '{own}'")
    if doc.get("collection_errors"):
        warnings.append(f"the test session had {len(doc['collection_errors'])} collection error(s): "
                        + "; ".join(doc["collection_errors"][:3]))
    if doc.get("ignored_ids"):
        warnings.append(f"ids in the test results that the registry lacks: {', '.join(doc['ignored_ids'])}")
    return results, doc


def weakening_problems(registry: rq.Registry, system: Any = None) -> list[str]:
    """How ``registry`` (with its targets) is weaker than the system's: the packaged registry with the system
    file's ``[targets]`` (the shipped system when None). Each line fails the gate and names the parameter."""
    system = system or default_system()
    reference = rq.load_registry(None).with_targets(system.targets(), source=f"{system.label} [targets]")
    return [f"weaker than the system's requirements: {w}" for w in registry_weakenings(reference, registry)]


def binding_problems(doc: Mapping[str, Any], digest: str, code: str, registry_sha: str, path: Path, *,
                     parameters_sha: str | None = None) -> list[str]:
    """Why requirement results do not belong to this run, code, registry and targets (empty when they do).

    ``parameters_sha``: the SHA-256 of the report's effective parameters (``Registry.parameters_sha256``):
    results judged on other targets (``--uav-el-targets`` / ``set_targets``) are refused.
    """
    ctx = doc.get("context") or {}
    out = []
    given = ctx.get("run_digest")
    if not given:
        out.append(f"{path}: the requirement results are not bound to a run (no run digest recorded)")
    elif given != digest:
        out.append(f"{path}: the requirement results were produced on other readouts (run digest {str(given)[:12]}, "
                   f"this run {digest[:12]})")
    if ctx.get("code_sha256") != code:
        out.append(f"{path}: the requirement results were produced on other code (code hash "
                   f"{str(ctx.get('code_sha256'))[:12]}, this code {code[:12]})")
    reg = doc.get("registry") or {}
    if reg.get("sha256") != registry_sha:
        out.append(f"{path}: the requirement results were produced with another requirement registry")
    elif parameters_sha is not None and reg.get("parameters_sha256") != parameters_sha:
        given = reg.get("targets")
        out.append(f"{path}: the requirement results were judged on other requirement targets (their overrides: "
                   f"{json.dumps(given, sort_keys=True) if isinstance(given, dict) else 'not recorded'}); "
                   "give the report the same targets (uav-el evidence --targets)")
    return out


def failure_detail(res: rq.RequirementResult, limit: int = 400) -> str:
    """The first line of a failed requirement's first failing test message (for a bound: which scenario, k of n,
    the bound, the target and the confidence), so the gate's verdict says why without opening the report."""
    first = next((t for t in res.tests if t.outcome in rq.FAILING and t.message), None)
    if first is None:
        return ""
    line = clean_message(first.message.strip().splitlines()[0].removeprefix("Failed: ").strip())
    return line if len(line) <= limit else line[: limit - 4].rsplit(" ", 1)[0] + " ..."  # cut at a word


@dataclass
class Gate:
    """The gate's verdict on a set of requirement results."""

    result: str
    text: str
    states: dict[str, str]
    failed: list[str]
    not_verified: list[str]
    waived: list[str]
    blocking: list[str]
    waivers: dict[str, dict[str, str]]
    problems: list[str]

    def exit_code(self, strict: bool, pdf_error: str | None) -> int:
        """1 when a failure is not waived, a requirement is not verified (unless undecidable at this run size), or
        there is a problem; with ``strict`` also when any requirement is not verified or the PDF is missing."""
        return 1 if self.blocking or self.problems or (strict and (self.not_verified or pdf_error)) else 0


def decide_gate(results: Mapping[str, rq.RequirementResult], problems: list[str], waivers: str | Path | None,
                strict: bool, *, undecidable: Sequence[str] = (), policy: Mapping[str, Any] | None = None) -> Gate:
    """The gate's verdict. A requirement not verified blocks unless it is in ``undecidable`` (the registry's
    ``size_limited`` on a run too small to decide them: ``assurance.evidence.context.undecidable_here``), or always
    with ``strict``. A bound the data already show missed is "failed" at any run size (``decide_rate_bound``), so
    it blocks like any failure and the text names it with its numbers (``failure_detail``). Waivers that cannot
    stand (``waiver_problems`` under ``policy``: the registry's ``waiver_owners`` and ``waiver_max_days``) and
    expired waivers are added to ``problems`` (the caller's list)."""
    states = {rid: r.state for rid, r in results.items()}
    failed = [rid for rid, s in states.items() if s == rq.FAILED]
    not_verified = [rid for rid, s in states.items() if s == rq.NOT_VERIFIED]
    waiver_list = load_waivers(waivers) if waivers else {}
    policy = policy or {}
    problems += waiver_problems(waiver_list, states, owners=policy.get("waiver_owners"),
                                max_days=int(policy.get("waiver_max_days") or DEFAULT_MAX_WAIVER_DAYS))
    expired = {rid for rid, w in waiver_list.items() if waiver_expired(w)}
    problems += [f"the waiver of {rid} (owner: {waiver_list[rid]['owner']}) expired ({waiver_list[rid]['expires']})"
                 for rid in sorted(expired)]
    waived = [rid for rid in failed if rid in waiver_list and rid not in expired and not strict]
    undecided_ok = [] if strict else [rid for rid in not_verified if rid in set(undecidable)]
    blocking = [rid for rid in failed if rid not in waived] + [rid for rid in not_verified if rid not in undecided_ok]
    result = "FAILED" if blocking or problems else ("WAIVED" if waived else "INCOMPLETE" if not_verified else "PASSED")
    parts = []
    if failed:
        parts.append(f"{len(failed)} requirement(s) failed ({', '.join(failed)})"
                     + (f", {len(waived)} waived" if waived else ""))
        parts += [f"{rid}: {why}" for rid in failed if rid not in waived and (why := failure_detail(results[rid]))]
    if not_verified:
        left = len(not_verified) - len(undecided_ok)
        parts.append(f"{len(not_verified)} not verified" + (
            f" ({len(undecided_ok)} undecidable at this run size)" if undecided_ok else "")
            + (f", {left} of them blocking" if left and undecided_ok else ""))
    text = "; ".join(parts) or "every requirement verified"
    if problems:
        text = f"{problem_count(problems)} (below); " + text
    return Gate(result, text, states, failed, not_verified, waived, blocking, waiver_list, problems)


def problem_count(problems: Sequence[str]) -> str:
    """The gate problems by kind: deviations from the certification basis not accepted (they open with
    :data:`DEVIATION`) and integrity problems (every other: results not bound or not signed, a state contradicting
    its tests, a waiver that cannot stand, a label set changed since the run, ...)."""
    deviations = sum(str(p).startswith(DEVIATION) for p in problems)
    parts = [f"{deviations} deviation(s) from the certification basis not accepted"] if deviations else []
    if len(problems) > deviations:
        parts.append(f"{len(problems) - deviations} integrity problem(s)")
    return " and ".join(parts)
