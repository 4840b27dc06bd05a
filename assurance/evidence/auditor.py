"""The auditor's part of the evidence report: the hazard log, the safety argument, the ISSRE 2022 metrics, the data
and model records and the AMLAS index, as finished records for the templates and for ``evidence.json``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from assurance.evidence.hazards import hazard_view, load_hazards


def auditor_context(inp: Any, gate: Any, hazards: str | Path | None = None) -> dict[str, Any]:
    """The auditor's sections of the report (``inp``: the report's ``Inputs``; ``gate``: its ``Gate``)."""
    log = load_hazards(hazards, inp.registry)
    return {"hazards": hazard_view(log, gate.states), "hazards_file": log.path.name,
            "hazards_sha256": log.sha256}


def auditor_document(context: dict[str, Any]) -> dict[str, Any]:
    """The auditor's sections as ``evidence.json`` holds them."""
    return {"hazards": {"file": context["hazards_file"], "sha256": context["hazards_sha256"],
                        "hazards": context["hazards"]}}
