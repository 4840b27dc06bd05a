"""The report's section registry: which sections the evidence report has, in which order, with their anchors,
their lines in the table of contents and the template that renders each. A new section (e.g. a monitor benchmark)
is one template file in ``evidence_templates/`` and one :func:`register_section` call (or an entry here); the
packaged ``report.html.j2`` lays out the table of contents and includes the templates in this order. The first page
(gate verdict, summary) is no section: the toolkit renders it itself (``render.COVER``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Section:
    """One section: its anchor (the HTML id its template gives it), its title in the table of contents, the
    template that renders it (several sections may share one) and the context value that must be set for it to
    be shown (empty: always shown)."""

    id: str
    title: str
    template: str
    when: str = ""


SECTIONS: list[Section] = [
    Section("identity", "What was assessed", "section_identity.html.j2"),
    Section("domain", "Operating domain and assumptions", "section_domain.html.j2"),
    Section("hazards", "Hazard log", "auditor_hazards.html.j2"),
    Section("argument", "Safety argument", "auditor_argument.html.j2"),
    Section("matrix", "Traceability matrix", "section_matrix.html.j2"),
    Section("tests", "Requirement tests", "section_tests.html.j2"),
    Section("checks", "Campaign evidence", "section_checks.html.j2"),
    Section("results", "Results table", "section_results.html.j2"),
    Section("issre", "Safety gain, residual hazard, availability cost", "auditor_issre.html.j2"),
    Section("plots", "Plots", "section_plots.html.j2"),
    Section("gallery", "Perturbations", "section_gallery.html.j2"),
    Section("examples", "Decisions and unsafe landings", "section_examples.html.j2"),
    Section("changes", "What changed", "section_changes.html.j2", when="baseline"),
    Section("benchmark", "Monitor benchmark", "section_benchmark.html.j2", when="benchmark"),
    Section("in-service", "In service", "section_in_service.html.j2", when="in_service"),
    Section("data-record", "Data-management record", "auditor_records.html.j2"),
    Section("model-log", "Model development log", "auditor_records.html.j2"),
    Section("amlas", "AMLAS index", "auditor_records.html.j2"),
    Section("files", "Files of this report", "section_files.html.j2"),
    Section("limitations", "Limitations", "section_limitations.html.j2"),
    Section("requirements", "Requirements (full text)", "section_requirements.html.j2"),
    Section("reproduce", "Reproduce", "section_reproduce.html.j2"),
    Section("faults", "Appendix: fault injection", "section_faults.html.j2", when="faults"),
]
"""The sections in report order."""


def register_section(section: Section, *, after: str | None = None) -> None:
    """Add ``section`` to the report, after the section with id ``after`` (default: before the appendix of
    fault injection, i.e. after "Reproduce"); ValueError for an id already registered or an unknown ``after``."""
    if any(s.id == section.id for s in SECTIONS):
        raise ValueError(f"report section {section.id!r} is already registered")
    anchor = after or "reproduce"
    at = next((i for i, s in enumerate(SECTIONS) if s.id == anchor), None)
    if at is None:
        raise ValueError(f"report section {anchor!r} (after=) is not registered")
    SECTIONS.insert(at + 1, section)


def outline(context: Mapping[str, Any]) -> dict[str, list[Any]]:
    """The context's ``sections`` (id and title of each shown section, for the table of contents) and
    ``section_templates`` (the templates to include, each once, in order)."""
    shown = [s for s in SECTIONS if not s.when or context.get(s.when)]
    return {"sections": [{"id": s.id, "title": s.title} for s in shown],
            "section_templates": list(dict.fromkeys(s.template for s in shown))}
