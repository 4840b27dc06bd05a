"""The evidence report (docs/architecture.md 4.7): what was assessed, against which requirements, with what result.

``generate(run, out, ...)`` reads a campaign run (manifest, readouts, results table), the requirement
registry and the requirement results of a test session (``uav-el verify RUN``, JSON
written by ``assurance.requirements.pytest_plugin``), and writes into ``out``:

- ``evidence.html``: self-contained (CSS inline, images as data URIs), rendered from the Jinja2
  templates in the ``evidence_templates`` package (immutable sandbox, autoescape on, undefined variables are
  errors); every requirement, hazard, test and artefact has an anchor, linked both ways (``navigation``,
  ``linking``: one inline filter script, allowed by the page's Content-Security-Policy);
- ``evidence.pdf``: the same HTML through WeasyPrint (skipped with a clear message if it is missing);
- ``evidence.json``: identity, requirement states, campaign checks and the results table, for tools;
- ``results.csv``: the results table the report shows; ``traceability.csv``: one row per (requirement,
  test) with outcome, state and artefact; ``SHA256SUMS``: the hashes of these files (and of
  ``junit.xml`` when the evidence step wrote one into ``out``);
- the PDF is PDF/A-3b with ``evidence.json``, ``results.csv``, ``traceability.csv``, ``junit.xml`` and
  ``SHA256SUMS`` attached (that copy of SHA256SUMS lists every file but the PDF itself).

Paths in the report and its JSON are relative to the project root when they lie under it.

Everything the templates show is computed in this package, as finished strings: the templates compute
nothing. Modules: ``report`` (``generate``), ``context`` (inputs and the template context), ``gate``
(binding and verdict), ``waivers``, ``matrix`` (the report's checks from the check registry, the
requirement matrix, traceability), ``identity`` (what was assessed, baseline comparison),
``sections`` (domain, results, sample size, limitations, examples), ``outline`` (the section registry: which
sections, in which order, rendered by which template), ``navigation`` (anchors, the test list with source
links, the report's files), ``render`` (HTML, PDF, files), ``linking`` (the last pass over the HTML: requirement
ids linked, the filter script and its Content-Security-Policy), ``text`` (formatting).
The gate (``EvidenceReport.exit_code``): 1 when a requirement is failed (and not waived), when the
requirement results are not bound to this run, code and registry (the run digest, code hash and
registry hash their test session recorded), when a state contradicts its own tests or this report's
check of the run, or when a waiver has expired; with ``strict`` (which ignores waivers) also when a
requirement is not verified or the PDF could not be written; else 0. A run whose shards fail
verification gets no report (``readouts.DamagedRunError``, exit 4 at the command line).
"""

from __future__ import annotations

from assurance.evidence.gate import GATE_CLASS, EvidenceReport, Gate, binding_problems, decide_gate
from assurance.evidence.matrix import TRACE_COLUMNS, traceability_rows
from assurance.evidence.render import (
    FAULTS_CSV,
    PDF_HINT,
    PDF_VARIANT,
    ROOT,
    TEMPLATE,
    TEMPLATES_DIR,
    environment,
    pdf_attachment_names,
    rel,
    render_html,
    render_report,
    write_pdf,
)
from assurance.evidence.report import EVIDENCE_FORMAT, generate
from assurance.evidence.text import STATE_CLASS, STATUS_CLASS, STATUS_TEXT, fmt, pct
from assurance.evidence.waivers import WAIVER_FIELDS, load_waivers, waiver_expired

__all__ = [
    "EVIDENCE_FORMAT",
    "FAULTS_CSV",
    "GATE_CLASS",
    "PDF_HINT",
    "PDF_VARIANT",
    "ROOT",
    "STATE_CLASS",
    "STATUS_CLASS",
    "STATUS_TEXT",
    "TEMPLATE",
    "TEMPLATES_DIR",
    "TRACE_COLUMNS",
    "WAIVER_FIELDS",
    "EvidenceReport",
    "Gate",
    "binding_problems",
    "decide_gate",
    "environment",
    "fmt",
    "generate",
    "load_waivers",
    "pct",
    "pdf_attachment_names",
    "rel",
    "render_html",
    "render_report",
    "traceability_rows",
    "waiver_expired",
    "write_pdf",
]
