"""The perturbations a system's work runs (docs/campaigns.md, "The system's perturbations"): ``none``, those of its
declared operating domain (``[odd] perturbations``: name -> maximum severity) and those its requirements need
(``[targets] required_perturbations``, else the packaged registry's, the paper's six), each marked inside or
outside the declared domain.

One plan feeds the campaign presets (their ``declared`` keyword), ``uav-el fit-gate`` and ``uav-el calibrate`` (the
inside ones, for a system file declaring its own), the run's manifest (which perturbation ran inside the domain) and
the report. Each runs at the presets' severity 3, or at its declared maximum when that is lower; a required one
outside the domain still runs, marked outside. For the embedded default (the shipped system: the five at severity 3,
the paper's six required) the plan is the paper's six in their usual order, so the shipped runs do not move.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from assurance.campaign.task import scenario_pairs
from assurance.perturbations import PAPER_PERTURBATIONS, PERTURBATIONS, TRAITS
from assurance.system import default_system
from el.geometry.odd import OperatingDomain

NONE = "none"
DECLARED = "declared"
"""The presets' keyword for the system's perturbations (the plan's, ``none`` excepted)."""
PRESET_SEVERITY = 3
"""The severity the presets run at (the paper's); a declared maximum below it is used instead."""
REGISTRY_REQUIRED: tuple[str, ...] = PAPER_PERTURBATIONS
"""The packaged registry's ``required_perturbations`` (``tests/test_requirements_plugin.py`` pins the two equal): what
a system file without ``[targets] required_perturbations`` is held to."""


@dataclass(frozen=True)
class Planned:
    """One perturbation of a system's plan."""

    name: str
    severity: int
    """The severity the work runs it at: the presets' 3, or its declared maximum when lower."""
    declared: int | None
    """Its declared maximum severity (None: not declared; ``none`` is always inside)."""
    required: bool
    """Named by the requirements' ``required_perturbations``."""

    @property
    def inside(self) -> bool:
        """Whether it runs inside the declared operating domain."""
        return self.name == NONE or (self.declared is not None and 1 <= self.severity <= self.declared)


def perturbation_plan(odd: OperatingDomain, required: Sequence[str] | None = None, *,
                      severity: int = PRESET_SEVERITY) -> tuple[Planned, ...]:
    """The plan of a declared domain and a required set (None: the registry's): ``none``, then every declared or
    required perturbation in ``assurance.perturbations`` order, each at ``severity`` capped at its declared maximum
    (a maximum of 0 declares nothing: such a perturbation runs only when required, at ``severity``, outside)."""
    needed = tuple(REGISTRY_REQUIRED if required is None else required)
    declared = dict(odd.perturbations)
    out = []
    for name in PERTURBATIONS:
        if name != NONE and not declared.get(name) and name not in needed:
            continue
        level = declared.get(name) if name != NONE else None
        sev = min(severity, level) if level else severity
        out.append(Planned(name, sev, level, name in needed))
    return tuple(out)


def system_plan(system: Any = None, *, severity: int = PRESET_SEVERITY) -> tuple[Planned, ...]:
    """The plan of a system (an ``assurance.system.System`` or a ``SystemFile``; None: the embedded default):
    its ``[odd] perturbations`` and ``[targets] required_perturbations`` (the registry's when the file sets none)."""
    if system is None:
        return default_plan() if severity == PRESET_SEVERITY else system_plan(default_system(), severity=severity)
    file = getattr(system, "file", system)
    odd = system.odd if isinstance(getattr(system, "odd", None), OperatingDomain) else file.odd()
    required = file.required_perturbations
    return perturbation_plan(odd, None if required is None else list(required), severity=severity)


@cache
def default_plan() -> tuple[Planned, ...]:
    """The embedded default system's plan: the paper's six at severity 3."""
    return system_plan(default_system())


def expand(items: str | Sequence[str], plan: Sequence[Planned]) -> tuple[str, ...]:
    """A preset's perturbation list with the keyword ``declared`` expanded to the plan's perturbations (``none``
    excepted: a preset names it), duplicates dropped."""
    names: list[str] = []
    for item in [items] if isinstance(items, str) else items:
        if item == DECLARED:
            names.extend(p.name for p in plan if p.name != NONE)
        else:
            names.append(str(item))
    return tuple(dict.fromkeys(names))


def severity_caps(plan: Sequence[Planned], perturbations: Iterable[str],
                  severities: Sequence[int]) -> dict[str, int] | None:
    """Per perturbation run, its declared maximum where that is below the highest of ``severities`` (it then runs at
    the severities up to it, else at it: ``assurance.campaign.task.scenario_pairs``); None when there is none."""
    top = max(severities)
    levels = {p.name: p.declared for p in plan}
    caps = {name: int(levels[name]) for name in perturbations
            if levels.get(name) and TRAITS[name].graded and int(levels[name]) < top}
    return caps or None


def fit_levels(system: Any) -> tuple[tuple[str, int], ...] | None:
    """What ``uav-el fit-gate`` and ``uav-el calibrate`` perturb their frames with: (name, severity) of the plan's
    perturbations inside the declared domain, ``none`` first, when the system file itself declares
    ``[odd] perturbations``; None (each command's own: the paper's six for the gate, clean frames for a card) for
    the embedded default and a file inheriting its declaration, so the shipped fits are reproduced as they were."""
    file = getattr(system, "file", system)
    if file is None or file.default or not file.declares_perturbations:
        return None
    return tuple((p.name, p.severity) for p in system_plan(system) if p.inside)


def domain_record(perturbations: Sequence[str], scenarios: Iterable[tuple[str, int]],
                  odd: OperatingDomain | None) -> dict[str, dict[str, Any]] | None:
    """The manifest's ``perturbation_domain``: per perturbation run, its declared maximum (None: not declared), the
    severities run and whether all of them lie inside the declared domain ``odd`` (None: none declared)."""
    if odd is None:
        return None
    out: dict[str, dict[str, Any]] = {
        name: {"declared_max": odd.perturbations.get(name), "severities": [], "inside": True}
        for name in perturbations}
    for name, sev in scenarios:
        out[name]["severities"].append(int(sev))
        out[name]["inside"] = out[name]["inside"] and odd.covers(name, int(sev))
    return out


def outside_lines(record: Mapping[str, Mapping[str, Any]] | None, plan: Sequence[Planned], where: str, *,
                  own_required: bool = True) -> list[str]:
    """One line per perturbation a campaign runs outside the declared domain of ``where`` (the system file): why it
    runs (asked for, or required: by the file's ``[targets] required_perturbations`` when ``own_required``, else
    by the packaged registry's) and that the run marks it."""
    needed = {p.name for p in plan if p.required}
    by = ("[targets] required_perturbations" if own_required else
          "the certification basis (the packaged registry's required_perturbations; the system file sets none)")
    out = []
    for name, rec in (record or {}).items():
        if rec["inside"]:
            continue
        why = ("not declared in its [odd] perturbations" if rec["declared_max"] is None else
               f"severity {max(rec['severities'])} is above its declared maximum {rec['declared_max']}")
        runs = f"required by {by}" if name in needed else "asked for"
        out.append(f"{name} is outside the declared operating domain of {where} ({why}): it runs ({runs}), and the "
                   "run marks it outside")
    return out


def outside_scenarios(manifest: Mapping[str, Any]) -> set[tuple[str, int]]:
    """The (perturbation, severity) scenarios of a run outside its declared domain, from its manifest's configuration
    (a run that declares no domain: none)."""
    cfg = manifest.get("config") or {}
    if cfg.get("odd") is None:
        return set()
    domain = OperatingDomain.from_dict(cfg["odd"])
    pairs = scenario_pairs(cfg.get("perturbations") or (), cfg.get("severities") or (3,), cfg.get("severity_caps"))
    return {(p, int(s)) for p, s in pairs if not domain.covers(p, int(s))}


__all__ = ["DECLARED", "NONE", "PRESET_SEVERITY", "REGISTRY_REQUIRED", "Planned", "default_plan", "domain_record",
           "expand", "fit_levels", "outside_lines", "outside_scenarios", "perturbation_plan", "severity_caps",
           "system_plan"]
