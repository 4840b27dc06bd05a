"""The AMLAS index: every artefact of the evidence package mapped to its AMLAS stage and artefact letter (AMLAS v1,
Hawkins et al. 2021: [A]-[E] scoping, [H]/[J] ML safety requirements, [L]-[Q] data management, [U]/[V]/[X] model
learning, [Z]/[AA] verification, [EE]/[FF] deployment; letters as on the AMLAS stage pages), with the file and
its SHA-256."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

ARTEFACTS = {
    "A": (1, "System safety requirements"), "B": (1, "Description of the operating environment"),
    "C": (1, "System description"), "D": (1, "ML component description"),
    "E": (1, "Safety requirements allocated to the ML component"),
    "H": (2, "ML safety requirements"), "J": (2, "ML safety requirements validation results"),
    "L": (3, "Data requirements"), "M": (3, "Data requirements justification report"),
    "N": (3, "Development data"), "O": (3, "Internal test data"), "P": (3, "Verification data"),
    "Q": (3, "Data generation log"),
    "U": (4, "Model development log"), "V": (4, "ML model"), "X": (4, "Internal test results"),
    "Z": (5, "ML verification results"), "AA": (5, "Verification log"),
    "EE": (6, "Operational scenarios"), "FF": (6, "Integration testing results"),
}
"""AMLAS artefact letter -> (stage, name)."""

IDENTITY_LETTERS = {
    "Requirement registry": ("A", "E", "H"), "System file": ("C",), "Weights": ("D", "V"), "Data": ("P",),
    "Requirement targets": ("H",), "Requirement test results": ("Z",), "Results table": ("Z", "FF"),
    "Run readouts": ("FF",), "Configuration": ("AA", "EE"),
}
"""The report's identity rows (``assurance.evidence.identity``) and the AMLAS artefacts they are."""


def entry(letter: str, item: str, path: str | None, sha256: str | None, cls: str = "") -> dict[str, Any]:
    """One index entry: the AMLAS letter's stage and name, what it is here, where, its hash."""
    stage, name = ARTEFACTS[letter]
    return {"stage": stage, "letter": letter, "artefact": name, "item": item, "path": path or "",
            "sha256": sha256 or "", "cls": cls}


def amlas_index(identity_rows: Sequence[Mapping[str, Any]], extra: Iterable[Mapping[str, Any]] = ()
                ) -> list[dict[str, Any]]:
    """The index, ordered by stage then letter: the identity rows mapped by ``IDENTITY_LETTERS`` plus ``extra``
    entries (hazard log, data and model records, junit, fault table)."""
    out = [entry(letter, row["item"], str(row.get("value", "")), row.get("sha256"))
           for row in identity_rows for letter in IDENTITY_LETTERS.get(row["item"], ())]
    out += [dict(e) for e in extra]
    order = list(ARTEFACTS)
    return sorted(out, key=lambda e: (e["stage"], order.index(e["letter"]), e["item"]))
