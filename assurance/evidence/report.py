"""``generate``: read the run and the requirement results, decide the gate, render and write the evidence report."""

from __future__ import annotations

import datetime as _dt
import json
import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from assurance import requirements as rq
from assurance.analysis.headline import REPRODUCIBILITY
from assurance.campaign.integrity import code_sha256
from assurance.evidence.acceptance import acceptance_rows, domain_source
from assurance.evidence.auditor import ARGUMENT_FILE, ISSRE_FILE, auditor_context, auditor_document
from assurance.evidence.benchmark_section import read_benchmark
from assurance.evidence.context import (
    Inputs,
    ReportOptions,
    campaign_context,
    commands,
    images_per_perturbation,
    not_size_limited,
    read_inputs,
    template_context,
    undecidable_here,
)
from assurance.evidence.gate import DEVIATION, EvidenceReport, Gate, decide_gate
from assurance.evidence.identity import baseline_view
from assurance.evidence.matrix import TRACE_COLUMNS, artefact_users, link_hazards, traceability_rows
from assurance.evidence.navigation import anchor, code_statement, files_view, req_anchor, tests_view
from assurance.evidence.render import (
    FAULTS_CSV,
    TemplateError,
    rel,
    render_report,
    write_csv_rows,
    write_pdf,
    write_text,
)
from assurance.evidence.signatures import check_results_signature
from assurance.evidence.text import jsonable
from assurance.inservice.section import read_in_service
from assurance.requirements.basis import class_category, deviations
from el.base.hashing import sha256_file
from el.classes.labels import UAVID

EVIDENCE_FORMAT = "uav-el-evidence/1"
log = logging.getLogger(__name__)


class _Files:
    """The files of a report folder."""

    def __init__(self, out: Path, csv_path: Path) -> None:
        self.html, self.json, self.pdf = out / "evidence.html", out / "evidence.json", out / "evidence.pdf"
        self.trace, self.junit, self.sums = out / "traceability.csv", out / "junit.xml", out / "SHA256SUMS"
        self.faults, self.csv = out / FAULTS_CSV, csv_path
        self.argument, self.issre = out / ARGUMENT_FILE, out / ISSRE_FILE

    def hashed(self) -> tuple[Path, ...]:
        """The files SHA256SUMS lists (those present)."""
        return (self.html, self.pdf, self.json, self.csv, self.trace, self.junit, self.faults, self.argument,
                self.issre)

    def written(self) -> tuple[Path, ...]:
        """The files this command writes (not ``junit.xml`` and ``faults.csv``, which ``verify`` and ``fault-table``
        leave there): removed together when the report is refused, so none is left that could pass for this run's."""
        return (self.html, self.pdf, self.json, self.sums, self.csv, self.trace, self.argument, self.issre)

    def attachments(self, faults: bool) -> list[Path]:
        """The files the PDF embeds."""
        return [self.json, self.csv, self.trace, self.junit, self.sums, self.argument, self.issre] + (
            [self.faults] if faults else [])


def _write_pdf(html: str, files: _Files, faults: bool, bounded: str | None = None) -> str | None:
    """The report's PDF (None, or why none was written); one that asks for a resource beyond the report's own
    files, or (``bounded``: the supplied template folder whose markup it lays out) one whose layout exceeds the
    limits of supplied content, takes the whole report with it (a ``TemplateError``)."""
    try:
        return write_pdf(html, files.pdf, files.attachments(faults), served=files.attachments(faults),
                         bounded=bounded)
    except TemplateError:  # RefusedResourceError, or the bounded layout refused
        _remove(files)
        raise


def _remove(files: _Files) -> None:
    """Remove every file this command writes (no report whose making was refused is left in --out)."""
    for f in files.written():
        f.unlink(missing_ok=True)


def _render_page(context: dict[str, Any], templates: Path | None, files: _Files, seconds: float | None
                 ) -> tuple[str, dict[str, Any] | None]:
    """The report's HTML and what supplied templates contributed (``render_report``); a refused template removes
    every file of the report from the folder (this run's tables and any earlier report: none is left that could
    pass for this run's) before it is raised."""
    try:
        return render_report(context, templates, seconds=seconds)
    except TemplateError:
        _remove(files)
        raise


@dataclass(frozen=True)
class Outcome:
    """What one writing of the report came to, for ``evidence.json`` (:func:`evidence_document`)."""

    created: str
    strict: bool
    files: _Files
    faults: bool
    n_unsafe: int
    n_unsafe_deployed: int | None
    pdf_error: str | None
    exit_code: int
    basis: list[Any] | None = None
    templates: dict[str, Any] | None = None


def evidence_document(inp: Inputs, gate: Gate, ident: dict[str, Any], base: dict[str, Any] | None,
                      outcome: Outcome) -> dict[str, Any]:
    """``evidence.json``: identity, gate, requirement states, the report's checks and the results table."""
    reg, results = inp.registry, inp.results
    created, strict, files, faults, n_unsafe = outcome.created, outcome.strict, outcome.files, outcome.faults, \
        outcome.n_unsafe
    pdf_error, exit_code, basis, templates = outcome.pdf_error, outcome.exit_code, outcome.basis, outcome.templates
    return {
        "format": EVIDENCE_FORMAT, "created": created, "run": rel(inp.run), "strict": strict,
        "gate": {"result": gate.result, "exit_code": exit_code, "counts": rq.summary_counts(gate.states.values()),
                 "failed": gate.failed, "waived": {rid: gate.waivers[rid] for rid in gate.waived},
                 "not_verified": gate.not_verified, "problems": inp.problems},
        "identity": ident,
        "parameters": reg.parameters,
        "requirements": {rid: {**results[rid].to_dict(), "text": reg[rid].text, "source": list(reg[rid].source),
                               "acceptance": reg[rid].acceptance} for rid in reg.ids},
        "checks": {ev.requirement: {"name": ev.name, "status": ev.status, "summary": ev.summary,
                                    "rows": list(ev.rows)} for ev in inp.checks.values()},
        "results": inp.table.to_dict("records"),
        "unsafe_landings": {"every_configuration": n_unsafe, "deployed": outcome.n_unsafe_deployed,
                            "deployed_configuration": inp.deployed},  # decisions onto unsafe ground, default included
        "baseline": base and {k: v for k, v in base.items() if k != "figures"},
        "warnings": inp.warnings,
        "files": {"html": rel(files.html), "pdf": None if pdf_error else rel(files.pdf), "csv": rel(files.csv),
                  "traceability": rel(files.trace), "junit": rel(files.junit) if files.junit.is_file() else None,
                  "faults": rel(files.faults) if faults else None},
        "pdf_error": pdf_error,
        "basis": {"deviations": [d.to_dict() for d in basis or []]},
        "templates": templates,  # None: the packaged templates only; else the supplied folder, its hash and use
    }


def _finish(files: _Files, document: dict[str, Any]) -> None:
    """Write evidence.json, then SHA256SUMS over every file of the report present."""
    write_text(files.json, json.dumps(jsonable(document), indent=2, allow_nan=False) + "\n")
    sums = [(p, sha256_file(p)) for p in files.hashed() if p.is_file()]
    write_text(files.sums, "".join(f"{h}  {p.name}\n" for p, h in sums))


def navigation_context(inp: Inputs, context: dict[str, Any], pdf: bool) -> dict[str, Any]:
    """The report's navigation (``assurance.evidence.navigation``): the tests with their sources, the files
    beside the report, the hazards of each requirement's row; the anchors linking them both ways."""
    tests = tests_view(inp.results, inp.req_doc, inp.out)
    link_hazards(context["matrix"], context["hazards"])
    for r in context["requirements"]:
        r["anchor"], r["text_anchor"] = req_anchor(r["id"]), anchor("reqtext", r["id"])
    changes = (context.get("baseline") or {}).get("by_requirement") or {}
    for r in context["matrix"]:  # what changed per requirement since the baseline (--baseline-requirements)
        c = changes.get(r["id"])
        r["since"] = "" if c is None else (f"baseline: {c['baseline']}" + (" (changed)" if c["changed"] else "")
                                           + (f"; {len(c['tests'])} test(s) changed" if c["tests"] else ""))
    return {"tests": tests, "tests_code": code_statement(inp.req_doc, code_sha256() if inp.req_doc else None),
            "files": files_view(inp.out, inp.run, str(rel(inp.run)), inp.csv_path.name, tests,
                                artefact_users(context["matrix"]), pdf)}


def _system_settings(system: Any, waivers: Any, templates: Any, targets: Any, targets_source: Any,
                     accepted: tuple[str, ...], system_templates: bool = False) -> tuple[Any, Any, Any, Any, list[Any]]:
    """The system file's waivers and targets where none were given (its report templates only when
    ``system_templates`` asks for them: an applicant-side convenience an auditor's report never takes unasked), and
    its deviations from the certification basis (``assurance.requirements.basis``) with the auditor's
    acceptances."""
    if system is None:
        return waivers, templates, targets, targets_source, deviations({}, accepted) if accepted else []
    waivers = system.waivers(str(waivers) if waivers else None)
    if system_templates and not templates:
        templates = system.report_settings()["templates"]
    if targets is None:  # the system file's [targets] (and R, beta, deployed monitor) judge the requirements
        targets, targets_source = system.targets(), targets_source or f"{system.label} [targets]"
    return waivers, templates, targets, targets_source, deviations(system.targets(), accepted,
                                                                   system.labels())


def _label_classes(system: Any) -> list[dict[str, str]]:
    """The label set's classes as the first page lists them: name, forbidden or safe, hazard category."""
    if system is None:
        labels = UAVID
    else:
        labels = system.labels()

    def category(c: Any) -> str:  # the category the basis judges it by: a well-known name's is pinned
        judged, pinned = class_category(c)
        if pinned is not None:
            return f"{pinned}, pinned" + (f"; declared {c.category}" if c.category not in (None, pinned) else "")
        return judged if c.category is not None else f"{judged}: none declared"

    return [{"name": c.name, "state": "forbidden" if c.forbidden else "safe", "category": category(c)}
            for c in labels.classes]


def _origins(system: Any) -> dict[str, Any]:
    """Where the system file sets each requirement parameter of its own (for the acceptance table)."""
    if system is None or system.default:
        return {}
    return {"origins": system.target_origins(), "label": str(system.label)}


def _report_context(inp: Inputs, gate: Gate, made: tuple[dict[str, Any], dict[str, Any] | None, str],
                    options: ReportOptions, *, basis: Any, bench: dict[str, Any] | None,
                    in_service: Any = None) -> dict[str, Any]:
    """What the templates render: the report's sections, the auditor's, the basis, the benchmark, the links.
    ``made``: the campaign's context, the baseline's view and the report's time."""
    campaign, base, created = made
    n_boot, pdf, system, accepted = options.n_boot, options.pdf, options.system, tuple(options.accepted_deviations)
    context = template_context(inp, gate, campaign, base, created, n_boot)
    context.update({**auditor_context(inp, gate, campaign["identity"], n_boot=n_boot), "label_classes":
                    _label_classes(system), "commands": commands(inp, accepted), "benchmark": bench,
                    "deviations": [{**d.to_dict(), "text": d.text()} for d in basis],
                    "parameters": acceptance_rows(inp.registry, basis, not_size_limited(inp),
                                                  shipped=system is None or system.default,
                                                  **_origins(system)),
                    "domain_source": domain_source(inp),
                    "reproducibility": REPRODUCIBILITY.text(images_per_perturbation(inp)),
                    "in_service": in_service and in_service.context(inp.check.digest)})  # assurance.inservice.section
    context.update(navigation_context(inp, context, pdf))
    return context


def generate(run: str | Path, out: str | Path, options: ReportOptions | None = None, **given: Any) -> EvidenceReport:
    """Write the evidence report of ``run`` into ``out`` and return what the gate says.

    ``options`` (``assurance.evidence.options.ReportOptions``), with any of its fields ``given`` by name over it
    (``generate(run, out, strict=True)``; an unknown name is a ``TypeError``):

    ``requirements``: the plugin's results JSON (default ``out/requirements.json``; without, all "not verified").
    ``baseline``, ``baseline_requirements``: an earlier run and its results JSON to compare with. ``system``: the system
    file assessed (``assurance.system.SystemFile``): its waivers, report settings and identity; a run or
    requirement results about another system file fail the gate. ``registry``: a path, or a loaded ``Registry``
    (with its targets); ``targets``: overrides of its parameters (``Registry.with_targets``, from
    ``targets_source``); the requirement results must have been judged on the same effective targets.
    ``trusted``: public keys by keyid (``assurance.attest.keys.load_trusted_keys``); with them the run's signed
    statement must verify (``UnattestedRunError`` otherwise) and the requirement results must carry the signed
    statement ``uav-el verify`` wrote, pinned to this run, registry, targets, waivers and system (a gate problem
    otherwise); without, the report says the signatures were not checked. ``accepted_deviations``: the targets
    the auditor accepts looser than the basis (``assurance.requirements.basis``); any other deviation fails the gate.
    ``benchmark``: a ``uav-el benchmark --out`` folder, shown as a section that never moves the gate.
    ``templates``, ``system_templates``, ``template_seconds``: supplied section templates (``render_report``).
    """
    o = replace(options or ReportOptions(), **given)
    baseline, baseline_requirements = o.baseline, o.baseline_requirements
    targets, targets_source, strict, waivers, pdf, n_boot = o.targets, o.targets_source, o.strict, o.waivers, o.pdf, \
        o.n_boot
    templates, system, trusted, accepted_deviations, benchmark = o.templates, o.system, o.trusted, \
        o.accepted_deviations, o.benchmark
    run, out = Path(run), Path(out)
    bench = read_benchmark(benchmark) if benchmark else None  # read first: a bad folder stops before any work
    service = read_in_service(o.in_service, trusted) if o.in_service else None  # an uav-el in-service --out folder
    waivers, templates, targets, targets_source, basis = _system_settings(
        system, waivers, templates, targets, targets_source, accepted_deviations, o.system_templates)
    inp = read_inputs(run, out, replace(o, waivers=waivers, templates=templates, targets=targets,
                                        targets_source=targets_source))
    inp.problems.extend(f"{DEVIATION}: {d.text()}" for d in basis if not d.accepted)
    if trusted is not None:
        check_results_signature(inp, waivers, trusted)
    campaign = campaign_context(inp)
    gate = decide_gate(inp.results, inp.problems, waivers, strict, undecidable=undecidable_here(inp),
                       policy=inp.registry.parameters)
    log.info("gate %s: %s (waivers: %s)", gate.result, gate.text, waivers or "none")
    base = (baseline_view(Path(baseline), inp.manifest, campaign["ident"], inp.table, inp.results, inp.registry,
                          Path(baseline_requirements) if baseline_requirements else None, n_boot)
            if baseline else None)
    created = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    context = _report_context(inp, gate, (campaign, base, created), o, basis=basis, bench=bench, in_service=service)
    files = _Files(out, inp.csv_path)
    html, supplied = _render_page(context, inp.templates, files, o.template_seconds)
    write_text(files.html, html)
    write_csv_rows(files.trace, traceability_rows(inp.registry, inp.results, run, inp.csv_path), TRACE_COLUMNS)
    files.pdf.unlink(missing_ok=True)  # never leave a PDF of an earlier report beside this one
    pdf_error = None if pdf else "PDF not written (--no-pdf)"
    faults = bool(context["faults"])

    def finish(pdf_error: str | None) -> int:
        exit_code = gate.exit_code(strict, pdf_error)
        outcome = Outcome(created=created, strict=strict, files=files, faults=faults, n_unsafe=campaign["n_unsafe"],
                          n_unsafe_deployed=campaign["n_unsafe_deployed"],
                          pdf_error=pdf_error, exit_code=exit_code, basis=basis, templates=supplied)
        _finish(files, {**evidence_document(inp, gate, campaign["ident"], base, outcome),
                        **auditor_document(context)})
        return exit_code

    exit_code = finish(pdf_error)  # the JSON says the PDF will be there; rewritten if it could not be
    if pdf:
        pdf_error = _write_pdf(html, files, faults, bounded=supplied["folder"] if supplied else None)
        exit_code = finish(pdf_error)
    return EvidenceReport(out=out, html=files.html, json=files.json, pdf=None if pdf_error else files.pdf,
                          pdf_error=pdf_error, states=gate.states, exit_code=exit_code, problems=inp.problems,
                          warnings=inp.warnings + ([pdf_error] if pdf and pdf_error else []),  # stderr, not stdout
                          waived=gate.waived, blocking=gate.blocking)
