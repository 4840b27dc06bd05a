"""The certification basis: the packaged registry's targets, and how a system's own targets deviate from them.

An applicant's system file may set its targets (``[targets]``, R and beta of ``[safety]``). Stricter ones are the
applicant's choice; a looser one (a higher unsafe-landing bound, a lower confidence, fewer images, a smaller
radius, a longer deadline...) is a **deviation** from the basis: listed on the report's first page with both
values, and failing the gate unless the auditor accepts it by name (``uav-el evidence --accept-deviation``,
recorded in the report). The deployed monitor and its card describe the system, not the basis: never deviations.
The label set is part of the basis too: every class declares a hazard category, and a class of a category the
registry's ``forbidden_categories`` lists (road, vehicle, building, water) declared safe is a deviation
(``class:NAME``), as is a safe class that declares no category.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

SYSTEM_CHOICES = ("deployed_monitor", "calibration_card", "forbidden_categories")
"""Parameters that name parts of the system assessed rather than a target: not compared with the basis."""


@dataclass(frozen=True)
class Deviation:
    """One target the system sets looser than the basis: its name, both values, and whether it was accepted."""

    name: str
    basis: Any
    system: Any
    accepted: bool = False

    def text(self) -> str:
        """One line: the parameter, the system's and the basis's values, and its state."""
        state = "accepted by the auditor" if self.accepted else \
            f"not accepted (the auditor may accept it with --accept-deviation {self.name})"
        return f"{self.name} = {_show(self.system)} is looser than the basis's {_show(self.basis)}: {state}"

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "basis": self.basis, "system": self.system, "accepted": self.accepted}


def _show(value: Any) -> str:
    return value if isinstance(value, str) else json.dumps(value, sort_keys=True, default=str)


def label_deviations(labels: Any, must_forbid: Iterable[str]) -> list[Deviation]:
    """The classes of ``labels`` declared safe although their hazard category is one the basis forbids
    (``must_forbid``: the registry's ``forbidden_categories``), or declared safe with no category at all (the basis
    cannot check them), named ``class:NAME``."""
    must = set(must_forbid)
    out = []
    for c in labels.classes:
        if c.forbidden:
            continue
        if c.category in must:
            out.append(Deviation(f"class:{c.name}", f"forbidden (category {c.category})", "declared safe"))
        elif c.category is None:
            out.append(Deviation(f"class:{c.name}", "a declared hazard category (el.label_tables.CATEGORIES)",
                                 "declared safe without one"))
    return out


def deviations(targets: Mapping[str, Any] | None, accepted: Iterable[str] = (), labels: Any = None) -> list[Deviation]:
    """The system's ``targets`` (``assurance.system.build.targets``) that are looser than the packaged registry's
    parameters, in the registry's order, then the classes of its ``labels`` that weaken the basis
    (:func:`label_deviations`); ``accepted``: the names the auditor accepts. An accepted name the system does not
    deviate on is a ``ValueError`` (a typo must not pass silently)."""
    from assurance.requirements.registry import load_registry
    from assurance.requirements.weakening import STRONGER, _weaker

    basis = load_registry(None)
    effective = basis.with_targets(dict(targets or {}), source="the system's targets").parameters
    accepted = set(accepted)
    out = []
    for name, ref in basis.parameters.items():
        if name in SYSTEM_CHOICES or name not in effective:
            continue
        given = effective[name]
        kind = STRONGER.get(name)
        if kind is None or not _weaker(kind, ref, given):
            continue
        out.append(Deviation(name, ref, given, accepted=name in accepted))
    if labels is not None:
        out += [Deviation(d.name, d.basis, d.system, accepted=d.name in accepted)
                for d in label_deviations(labels, basis.parameters.get("forbidden_categories") or ())]
    unknown = sorted(accepted - {d.name for d in out})
    if unknown:
        raise ValueError(f"--accept-deviation {', '.join(unknown)}: the system does not deviate from the basis on "
                         f"{'it' if len(unknown) == 1 else 'them'}"
                         + (f" (its deviations: {', '.join(d.name for d in out)})" if out else " (it has none)"))
    return out


__all__ = ["SYSTEM_CHOICES", "Deviation", "deviations", "label_deviations"]
