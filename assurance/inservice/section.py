"""The evidence report's "In service" section (``uav-el evidence --in-service DIR``): a signed in-service report read
back, its statement checked, its numbers passed to the section's template (``section_in_service.html.j2``).

Only ``in-service.json`` is read (bounded) and its signed statement checked (``report.check_attestation``): an
altered, unsigned or untrusted report is shown as such, never as evidence; one about another run (its pinned run
digest is not the report's) says so. The section never moves the certification gate.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from assurance.inservice.report import FORMAT, JSON_NAME, MAX_DOCUMENT_BYTES, check_attestation
from el.base import userfiles


class InServiceFolderError(ValueError):
    """A folder the report cannot read as an in-service report: one line naming it and the problem."""


@dataclass(frozen=True)
class InServiceSection:
    """A read in-service report: its document, where it lies, its SHA-256, and what its signature check found."""

    folder: Path
    doc: dict[str, Any]
    sha256: str
    predicate: dict[str, Any]
    problems: list[str]
    checked: bool

    def context(self, run_digest: str | None) -> dict[str, Any]:
        """What the section's template renders, with ``run_digest`` the digest of the run the evidence report
        judges (a comparison with another run is named as such)."""
        d = self.doc
        pinned = self.predicate.get("run_digest")
        other_run = bool(self.checked and pinned and run_digest and pinned != run_digest)
        return {"folder": str(self.folder), "sha256": self.sha256, "verdict": d.get("verdict"),
                "records": d.get("records"), "damaged": d.get("damaged"), "logs": d.get("logs") or [],
                "monitor": d.get("monitor"), "spis": d.get("spis") or [], "undermined": d.get("undermined") or [],
                "signed_by": self.predicate.get("signed_by"), "checked": self.checked, "problems": self.problems,
                "other_run": other_run, "pinned_run": pinned,
                "trusted": self.checked and not self.problems and not other_run}


def read_in_service(folder: str | Path, trusted: Mapping[str, Any] | None) -> InServiceSection:
    """The in-service report in ``folder`` (``uav-el in-service --out``), its statement checked against ``trusted``
    (None: not checked, and the section says so); InServiceFolderError for a folder without a readable report."""
    folder = Path(folder)
    path = folder / JSON_NAME
    if not folder.is_dir():
        raise InServiceFolderError(f"--in-service {folder}: not a folder (give uav-el in-service's --out)")
    try:
        raw = userfiles.read_bytes(path, what="in-service report", max_bytes=MAX_DOCUMENT_BYTES)
        doc = json.loads(raw.decode("utf-8"))
    except (userfiles.UserFileError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InServiceFolderError(f"{path}: not an in-service report ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InServiceFolderError(f"{path}: not an in-service report (format {FORMAT} expected)")
    predicate, problems = check_attestation(folder, trusted) if trusted is not None else ({}, [])
    import hashlib

    return InServiceSection(folder, doc, hashlib.sha256(raw).hexdigest(), predicate, problems, trusted is not None)


__all__ = ["InServiceFolderError", "InServiceSection", "read_in_service"]
