"""The report's view of requirements: the campaign checks it runs, the requirement matrix, the traceability rows.

Which check judges which requirement, and which artefacts it relies on, comes from the check registry
(``assurance.requirements.CHECKS``): this module names no requirement.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from assurance import requirements as rq
from assurance.evidence.navigation import (
    anchor,
    clean_message,
    message_view,
    outcome_class,
    req_anchor,
    short_name,
    status_summary,
)
from assurance.evidence.render import rel
from assurance.evidence.text import STATE_CLASS, STATUS_CLASS, STATUS_TEXT, fmt

ARTEFACT_TEXT = {"results_table": "results table {csv}", "report": "evidence.json (identity) and this report"}
"""How the matrix names each artefact a check relies on (``assurance.requirements.ARTEFACTS``)."""


def run_checks(registry: rq.Registry, ctx: rq.CheckContext) -> dict[str, rq.Evidence]:
    """The report's own campaign checks of the run: every registered ``in_report`` check of a registry requirement."""
    return {c.requirement: c(ctx) for c in rq.CHECKS.values() if c.in_report and c.requirement in registry}


def check_problems(checks: Mapping[str, rq.Evidence], results: Mapping[str, rq.RequirementResult],
                   problems: list[str], warnings: list[str]) -> None:
    """Compare the test results with the report's checks: a verified claim the check refutes is a problem (it
    fails the gate), a failed one the check passes a warning."""
    for rid, ev in checks.items():
        state = results[rid].state
        if state == rq.VERIFIED and ev.status != rq.PASS:  # a claim this report can refute: never passes
            problems.append(f"{rid}: the test results say verified, this report's own check of the run says "
                            f"{STATUS_TEXT[ev.status]} ({ev.summary})")
        elif ev.status == rq.PASS and state == rq.FAILED:
            warnings.append(f"{rid}: the test results ({state}) disagree with the campaign check on this run "
                            f"({STATUS_TEXT[ev.status]}): were they produced on another run?")


def check_view(ev: rq.Evidence) -> dict[str, Any]:
    """A check's record as the report shows it (finished strings, at most 60 rows)."""
    def cell(v: Any) -> str:
        if isinstance(v, bool):
            return "yes" if v else "no"
        if isinstance(v, float):
            return fmt(v, 4) if abs(v) < 10 else fmt(v, 1)
        return "n/a" if v is None else str(v)

    return {"id": ev.requirement, "anchor": anchor("check", ev.requirement), "name": ev.name,
            "status": STATUS_TEXT[ev.status], "status_class": STATUS_CLASS[ev.status],
            "summary": clean_message(ev.summary),
            "columns": [c.replace("_", " ") for c in ev.columns],
            "rows": [[cell(r.get(c)) for c in ev.columns] for r in ev.rows[:60]],
            "more": f"{len(ev.rows) - 60} more rows in evidence.json" if len(ev.rows) > 60 else ""}


def matrix(registry: rq.Registry, results: Mapping[str, rq.RequirementResult],
           checks: Mapping[str, rq.Evidence], run: Path, csv_name: str) -> list[dict[str, Any]]:
    """The requirement -> test -> result matrix: one row per requirement with its anchor, tests (each with its
    anchor and full message), artefacts (with the anchors of their entries in the report's file list) and check."""
    rows = []
    for req in registry:
        res = results[req.id]
        files = list(dict.fromkeys(t.nodeid.split("::")[0] for t in res.tests))
        links = [{"text": f"test file {f}", "key": f"test:{f}"} for f in files]
        if "campaign" in req.verification_kind:
            links.append({"text": f"campaign run {run}", "key": "run"})
        links += [{"text": ARTEFACT_TEXT[a].format(csv=csv_name), "key": csv_name if a == "results_table" else
                   "evidence.json"} for a in rq.artefacts_of(req.id)]
        for link in links:
            link["anchor"] = anchor("art", link["key"])
        check = checks.get(req.id)
        rows.append({
            "id": req.id, "anchor": req_anchor(req.id), "text_anchor": anchor("reqtext", req.id),
            "title": req.title, "method": req.verification_method, "acceptance": req.acceptance,
            "state": res.state, "state_class": STATE_CLASS[res.state], "reason": res.reason,
            "short_reason": short_reason(res),
            "tests": [{"nodeid": t.nodeid, "name": short_name(t.nodeid), "anchor": anchor("test", t.nodeid),
                       "outcome": t.outcome, "outcome_class": outcome_class(t.outcome),
                       "message": clean_message(t.message), "msg": message_view(t.message)} for t in res.tests],
            "artefacts": [link["text"] for link in links], "artefact_links": links,
            "check": (f"campaign check: {status_summary(STATUS_TEXT[check.status], check.summary)}" if check else ""),
            "check_anchor": anchor("check", req.id) if check else "",
            "hazards": [],  # filled from the hazard log (navigation.link_hazards)
        })
    return rows


def artefact_users(rows: list[dict[str, Any]]) -> dict[str, list[str]]:
    """Artefact key -> the requirements whose matrix row names it (the way back from an artefact)."""
    users: dict[str, list[str]] = {}
    for r in rows:
        for link in r["artefact_links"]:
            users.setdefault(link["key"], []).append(r["id"])
    return users


def link_hazards(rows: list[dict[str, Any]], hazards: list[dict[str, Any]]) -> None:
    """Give each matrix row the hazards its requirement mitigates, and each hazard's mitigations their anchors."""
    by_req: dict[str, list[dict[str, str]]] = {}
    for h in hazards:
        h["anchor"] = anchor("haz", h["id"])
        for m in h["mitigations"]:
            m["anchor"] = req_anchor(m["id"])
            by_req.setdefault(m["id"], []).append({"id": h["id"], "anchor": h["anchor"]})
    for r in rows:
        r["hazards"] = by_req.get(r["id"], [])


def short_reason(res: rq.RequirementResult) -> str:
    """The state's reason without the test details (the tests column shows them)."""
    if not res.tests:
        return res.reason
    n = len(res.tests)
    counts = Counter(t.outcome for t in res.tests)
    return ", ".join(f"{k} {v}" for v, k in sorted(((v, k) for k, v in counts.items()), reverse=True)) + f" (of {n})"


TRACE_COLUMNS = ("requirement", "test", "outcome", "state", "artefact")


def traceability_rows(registry: rq.Registry, results: Mapping[str, rq.RequirementResult], run: Path,
                      csv_path: Path) -> list[dict[str, str]]:
    """One row per (requirement, claiming test): outcome, the requirement's state, the artefact it read."""
    rows = []
    for req in registry:
        res = results[req.id]
        campaign = "campaign" in req.verification_kind
        for t in res.tests or [None]:
            test_file = t.nodeid.split("::")[0] if t else ""
            reads_table = "results_table" in rq.artefacts_of(req.id)
            artefact = (rel(csv_path) if reads_table else rel(run)) if campaign else test_file
            rows.append({"requirement": req.id, "test": t.nodeid if t else "", "outcome": t.outcome if t else "",
                         "state": res.state, "artefact": artefact or ""})
    return rows
