"""The report's account of what the requirements were judged against: the acceptance parameters (the certification
basis's value beside the system's, where each comes from, its mark against the basis) and whose values fill the
registry's wording of the operating domain. Each fact says its source (issue 60: a system file's values had been
attributed to the registry)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from assurance.evidence.render import rel


def parameter_text(v: Any) -> str:
    """A registry parameter as the report shows it."""
    if v is None:
        return "none"
    if isinstance(v, list):
        return ", ".join(map(str, v))
    if isinstance(v, dict):
        return ", ".join(f"{a} {b:.0%}" for a, b in v.items())
    return str(v)


SYSTEM_OWN = ("calibration_card",)
"""Parameters that name a file of the system itself: the basis has no value of them for another system."""


UNORDERED = ("deployed_monitor", "calibration_card")
"""Parameters that are a choice, not a bound: a system's own value is neither looser nor stricter than the basis."""


def acceptance_rows(reg: Any, deviations: Sequence[Any], decided_by: Mapping[str, str] | None = None,
                    *, shipped: bool = True, origins: Mapping[str, str] | None = None,
                    label: str = "") -> list[dict[str, str]]:
    """The acceptance parameters the requirements were judged on, each with the basis's value (the packaged
    registry's) beside the system's, where the system's comes from (the registry when the system sets none, else
    the targets' source) and its mark against the basis (a deviation, accepted or not, from
    ``assurance.requirements.basis``; a value the system sets that is no looser is marked as differing only;
    ``decided_by``: the size-limited requirements no run size decides here, :func:`not_size_limited`; ``shipped``:
    whether the system is the shipped one, whose own files the registry names; ``origins``: where the system file
    ``label`` sets each of its own, ``assurance.system.build.target_origins``)."""
    devs = {d.name: d for d in deviations}
    rows = []
    for k, v in reg.parameters.items():
        base = reg.defaults.get(k)
        if k in SYSTEM_OWN and not shipped:  # the registry's value is the shipped system's own file
            base = "the system's own (the registry names the shipped system's)"
        own = k in reg.targets
        dev = devs.get(k)
        mark = ("deviation, accepted" if dev.accepted else "deviation") if dev is not None else \
            "" if not own or v == base else "the system's own choice" if k in UNORDERED else \
            "set by the system, no looser than the basis"
        if k == "size_limited" and decided_by:  # what no run size decides here is not limited by size
            mark = "; ".join([mark] * bool(mark) + [f"{rid} not here: {why}" for rid, why in decided_by.items()])
        rows.append({"name": k.replace("_", " "), "value": parameter_text(v),
                     "basis": "not set" if base is None else parameter_text(base),
                     "source": (f"{label} {origins[k]}".strip() if origins and k in origins else
                                reg.targets_source or "the system's targets") if own else "the registry (basis)",
                     "mark": mark})
    return rows


def domain_source(inp: Any) -> str:
    """Where the operating domain's values come from, in words: the registry gives the wording only."""
    sysf = inp.system
    if sysf is None or sysf.default:
        return "the embedded default system (the shipped system)"
    return f"the system file {sysf.label if sysf.path is None else rel(sysf.path)}"
