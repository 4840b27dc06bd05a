"""What the evidence step checks of the signed requirement results: signed by a trusted key, unaltered, and
pinned to this run, its signed campaign statement, this registry and targets, these waivers and this system."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from assurance.requirements.attestation import check_results_attestation, results_pins


def results_signature_problems(inp: Any, waivers: str | Path | None,
                               trusted: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """(the signed predicate, gate problems) of the report's requirement results; none when there are none."""
    if inp.req_path is None:
        return {}, []
    junit = inp.req_path.with_name("junit.xml")
    registry = {"sha256": inp.registry.sha256, "parameters_sha256": inp.registry.parameters_sha256}
    pins = results_pins(inp.run, inp.manifest, registry, inp.check.digest, waivers)
    return check_results_attestation(inp.req_path, trusted, pins, junit=junit if junit.is_file() else None)


def check_results_signature(inp: Any, waivers: str | Path | None, trusted: Mapping[str, Any]) -> None:
    """Add the results' signature problems to the gate's and record who signed them (``inp.results_signed_by``)."""
    signed, problems = results_signature_problems(inp, waivers, trusted)
    inp.problems.extend(problems)
    inp.results_signed_by = signed.get("signed_by")
