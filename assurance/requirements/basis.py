"""The certification basis: the packaged registry's targets, and how a system's own targets deviate from them.

An applicant's system file may set its targets (``[targets]``, R and beta of ``[safety]``). Stricter ones are the
applicant's choice; a looser one (a higher unsafe-landing bound, a lower confidence, fewer images, a smaller
radius, a longer deadline...) is a **deviation** from the basis: listed on the report's first page with both
values, and failing the gate unless the auditor accepts it at its value
(``uav-el evidence --accept-deviation NAME=VALUE``, recorded in the report; a VALUE that is not the system's accepts
nothing). The deployed monitor and its card describe the system, not the basis: never deviations.

The label set is part of the basis too. The basis owns the hazard categories of the well-known class names
(``el.classes.class_names.PINNED_CATEGORIES``: road, street, paved area, car, building, person, water, ...; compared
once
NFKC-normalised and case-folded, a look-alike of one is refused when the set is read); another class takes the
category it declares, or ``unknown`` when it declares none. A deviation (``class:NAME``) is a class of a category
the registry's ``forbidden_categories`` lists (road, vehicle, building, water, obstacle) declared safe, a safe class of
category ``unknown`` (declared so, or declaring none: what the ground is was never said), or a class declaring
another category than the one its name pins. The basis itself accepts the safe ``unknown`` classes its registry lists
in ``safe_unknown_accepted`` (each by its label set's content SHA-256: UAVid's clutter), shown on page 1 as such.

Colours are part of what a reader trusts: a safe class painted in the colour a well-known label set (the packaged
presets: UAVid, Semantic Drone) gives one of its forbidden classes (``colour:NAME``) is a deviation too: label maps
drawn in that palette would make its road ground this set's safe class.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

from assurance.campaign.label_pin import label_set_sha256
from assurance.requirements.registry import load_registry
from assurance.requirements.weakening import STRONGER, _weaker
from el.classes.class_names import class_key, pinned_category
from el.classes.labels import label_presets, load_label_set

SYSTEM_CHOICES = ("deployed_monitor", "calibration_card", "forbidden_categories")
"""Parameters that name parts of the system assessed rather than a target: not compared with the basis."""
SAFE, FORBIDDEN = "safe", "forbidden"
"""The value of a class deviation (``--accept-deviation class:NAME=safe``): the class's state in the label set."""
UNKNOWN = "unknown"


@dataclass(frozen=True)
class Deviation:
    """One way the system is looser than the basis: its name, both values, what the auditor accepted.

    ``value`` is what ``--accept-deviation NAME=VALUE`` must give (the system's value; for a class its state,
    ``safe`` or ``forbidden``); None: ``system``. ``given``: the VALUE the auditor gave for this name; the deviation
    is ``accepted`` only when it is the system's value (:func:`value_matches`)."""

    name: str
    basis: Any
    system: Any
    accepted: bool = False
    value: Any = None
    given: str | None = None
    relation: str = "is looser than"
    accepted_by: str | None = None  # the basis's own entry that accepts it (``safe_unknown_accepted``), if any

    @property
    def bound(self) -> Any:
        """The value an acceptance binds (``value``, else ``system``)."""
        return self.system if self.value is None else self.value

    def acceptance(self) -> str:
        """The option that accepts this deviation at the system's value."""
        return f"--accept-deviation {self.name}={value_text(self.bound)}"

    def text(self) -> str:
        """One line: the parameter, the system's and the basis's values, and its state (for an accepted one, what
        the auditor accepted; for a value that is not the system's, both)."""
        if self.accepted_by is not None and self.given is None:
            state = f"accepted by the certification basis ({self.accepted_by})"
        elif self.accepted:
            state = f"accepted by the auditor at this value ({self.name}={self.given})"
        elif self.given is not None:
            state = (f"not accepted: the auditor accepted {self.name}={self.given}, but the system's value is "
                     f"{value_text(self.bound)}")
        else:
            state = f"not accepted (the auditor may accept it with {self.acceptance()})"
        return f"{self.name} = {_show(self.system)} {self.relation} the basis's {_show(self.basis)}: {state}"

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "basis": self.basis, "system": self.system, "accepted": self.accepted,
                "value": self.bound, "accepted_value": self.given, "accepted_by": self.accepted_by}


def _show(value: Any) -> str:
    return value if isinstance(value, str) else json.dumps(value, sort_keys=True, default=str)


def value_text(value: Any) -> str:
    """A value as ``--accept-deviation NAME=VALUE`` spells it: a number or a string as it is, ``true``/``false``,
    a list as its items joined by commas, a mapping as JSON."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | tuple):
        return ",".join(map(str, value))
    return _show(value)


def _same_number(a: Any, b: Any) -> bool:
    try:
        x, y = float(a), float(b)
    except (TypeError, ValueError):
        return False
    return math.isfinite(x) and x == y and not isinstance(a, bool) and not isinstance(b, bool)


def value_matches(bound: Any, text: str) -> bool:
    """Whether the auditor's VALUE ``text`` is the system's value ``bound``: numbers numerically (``0.06`` is
    ``0.060``), strings exactly, a list as comma-separated items in any order, a mapping as JSON (numbers in it
    numerically)."""
    if isinstance(bound, bool):
        return text.strip().lower() == value_text(bound)
    if isinstance(bound, int | float):
        return _same_number(text.strip(), bound)
    if isinstance(bound, str):
        return text == bound
    if isinstance(bound, list | tuple):
        items = [t.strip() for t in text.split(",")] if text.strip() else []
        return sorted(items) == sorted(str(v) for v in bound)
    if isinstance(bound, Mapping):
        try:
            given = json.loads(text)
        except ValueError:
            return False
        return isinstance(given, dict) and set(given) == set(bound) and all(
            _same_number(given[k], v) if isinstance(v, int | float) else given[k] == v for k, v in bound.items())
    return text == _show(bound)


def class_category(c: Any) -> tuple[str, str | None]:
    """(the category the basis judges class ``c`` by, the category its name pins or None): the pinned one for a
    well-known name, else the one it declares, else ``unknown``."""
    pinned = pinned_category(c.name)
    return pinned or c.category or UNKNOWN, pinned


def _class_deviation(c: Any, must: set[str]) -> Deviation | None:
    state = FORBIDDEN if c.forbidden else SAFE
    category, pinned = class_category(c)
    declared = c.category
    redeclared = pinned is not None and declared is not None and declared != pinned
    why = f", pinned for the name {c.name!r}" if pinned is not None else ""
    name = f"class:{c.name}"
    if state == SAFE and category in must:
        return Deviation(name, f"forbidden (category {category}{why})",
                         "declared safe" + (f" with category {declared}" if redeclared else ""), value=state)
    if state == SAFE and pinned is None and declared is None:
        return Deviation(name, f"forbidden (category {UNKNOWN}: a class the basis does not know that declares no "
                               "hazard category, el.classes.label_tables.CATEGORIES)", "declared safe without one",
                         value=state)
    if state == SAFE and category == UNKNOWN:
        return Deviation(name, f"forbidden (category {UNKNOWN}: what the ground is, is not said; the basis knows no "
                               "unknown ground to be safe)", f"declared safe with category {UNKNOWN}", value=state)
    if redeclared:
        return Deviation(name, f"category {pinned} ({why[2:]})", f"{state}, declared category {declared}",
                         value=state, relation="differs from")
    return None


def _rgb_text(rgb: Iterable[int]) -> str:
    return "RGB(" + ", ".join(str(int(v)) for v in rgb) + ")"


def well_known_forbidden_colours() -> dict[tuple[int, int, int], list[str]]:
    """Colour -> ``"CLASS (SET)"`` of every forbidden class of the well-known label sets: the packaged presets
    (``el.classes.labels.label_presets``: UAVid, Semantic Drone), read with their own checks."""
    out: dict[tuple[int, int, int], list[str]] = {}
    for preset in label_presets():
        labels = load_label_set(preset)
        for c in labels.classes:
            if c.forbidden:
                out.setdefault(tuple(int(v) for v in c.rgb), []).append(f"{c.name} ({labels.name})")
    return out


def colour_deviations(labels: Any, must_forbid: Iterable[str] = ()) -> list[Deviation]:
    """The safe classes of ``labels`` painted in a colour a well-known label set gives one of its forbidden classes
    (:func:`well_known_forbidden_colours`), named ``colour:NAME``; the value an auditor accepts is the colour,
    ``R,G,B``. A class whose category the basis forbids (``must_forbid``) is left out: declared safe, it is already
    the deviation ``class:NAME``."""
    known = well_known_forbidden_colours()
    must = set(must_forbid)
    found = []
    for c in labels.classes:
        rgb = tuple(int(v) for v in c.rgb)
        if c.forbidden or rgb not in known or class_category(c)[0] in must:
            continue
        found.append(Deviation(f"colour:{c.name}", "no safe class in a colour a well-known label set gives a forbidden "
                               "class", f"safe, painted {_rgb_text(rgb)}, the colour of {', '.join(known[rgb])}",
                               value=",".join(map(str, rgb)), relation="departs from"))
    return found


def _basis_accepts(labels: Any, accepted: Iterable[str]) -> dict[str, str]:
    """``{class:NAME: why}`` of the safe ``unknown`` classes of ``labels`` the basis itself accepts: its registry's
    ``safe_unknown_accepted`` entries ``SHA256:NAME`` naming this set's content SHA-256."""
    entries = [str(e).partition(":") for e in accepted or ()]
    if not entries:
        return {}
    sha = label_set_sha256(labels)
    return {f"class:{name}": (f"registry parameter safe_unknown_accepted: class {name!r} of the label set "
                              f"{labels.name!r}, content SHA-256 {sha[:12]}")
            for digest, _, name in entries if digest == sha}


def label_deviations(labels: Any, must_forbid: Iterable[str], accepted_unknown: Iterable[str] = ()) -> list[Deviation]:
    """The classes of ``labels`` that weaken the basis, named ``class:NAME``: declared safe although their hazard
    category is one the basis forbids (``must_forbid``: the registry's ``forbidden_categories``; a well-known
    name's category is the pinned one, whatever the set declares), declared safe with the category ``unknown``
    (declared, or no category and a name the basis does not know), or declaring another category than their name's
    pinned one; then the safe classes in a well-known forbidden class's colour (:func:`colour_deviations`).
    ``accepted_unknown``: the registry's ``safe_unknown_accepted`` (``SHA256:NAME``): a safe ``unknown`` class it
    names for this very set is a deviation the basis accepts (``accepted_by`` says where)."""
    must = set(must_forbid)
    by_basis = _basis_accepts(labels, accepted_unknown)
    found = []
    for c in labels.classes:
        d = _class_deviation(c, must)
        if d is None:
            continue
        if d.name in by_basis and class_category(c)[0] == UNKNOWN and not c.forbidden:
            d = replace(d, accepted=True, accepted_by=by_basis[d.name])
        found.append(d)
    return found + colour_deviations(labels, must)


def _name_key(name: str) -> str:
    """How an acceptance's NAME is compared with a deviation's: a class's (``class:``, ``colour:``) as class names are
    compared everywhere (``el.classes.class_names.class_key``: ``class:strasse`` is ``class:Straße``), a target's as
    written."""
    kind, sep, rest = name.partition(":")
    return f"{kind}:{class_key(rest)}" if sep and kind in ("class", "colour") else name


def _offers(accepted: Iterable[str], found: list[Deviation]) -> dict[str, str]:
    """``{name: VALUE}`` of the auditor's ``NAME=VALUE`` acceptances; ValueError for a plain NAME (one line giving
    the form), a name given twice, or a name the system does not deviate on."""
    by_name = {d.name: d for d in found}
    by_key = {_name_key(n): n for n in by_name}  # a class named as the rest of the toolkit compares class names
    out: dict[str, str] = {}
    unknown = []
    for item in map(str, accepted):
        given, _, _ = item.partition("=")
        name = by_key.get(_name_key(given)) if "=" in item else None
        if _name_key(item) in by_key or "=" not in item:
            item = by_key.get(_name_key(item), item)
            hint = f" (here: {by_name[item].acceptance()})" if item in by_name else ""
            raise ValueError(f"--accept-deviation {item}: give the value you accept, --accept-deviation NAME=VALUE"
                             f"{hint}; a deviation is accepted only at the value the system sets")
        if name is None:
            unknown.append(item.partition("=")[0])
            continue
        if name in out:
            raise ValueError(f"--accept-deviation {name}: given twice ({name}={out[name]}, {item}); give it once")
        out[name] = item[len(given) + 1:]
    if unknown:
        raise ValueError(f"--accept-deviation {', '.join(unknown)}: the system does not deviate from the basis on "
                         f"{'it' if len(unknown) == 1 else 'them'}"
                         + (f" (its deviations: {', '.join(d.name for d in found)})" if found else " (it has none)"))
    return out


def deviations(targets: Mapping[str, Any] | None, accepted: Iterable[str] = (), labels: Any = None) -> list[Deviation]:
    """The system's ``targets`` (``assurance.system.build.targets``) that are looser than the packaged registry's
    parameters, in the registry's order, then the classes of its ``labels`` that weaken the basis
    (:func:`label_deviations`); ``accepted``: the auditor's acceptances, ``NAME=VALUE`` each (a deviation is
    accepted only when VALUE is the system's value, :func:`value_matches`). A plain NAME, or a name the system does
    not deviate on, is a ``ValueError`` (a typo must not pass silently)."""
    basis = load_registry(None)
    effective = basis.with_targets(dict(targets or {}), source="the system's targets").parameters
    found = []
    for name, ref in basis.parameters.items():
        if name in SYSTEM_CHOICES or name not in effective:
            continue
        given = effective[name]
        kind = STRONGER.get(name)
        if kind is None or not _weaker(kind, ref, given):
            continue
        found.append(Deviation(name, ref, given))
    if labels is not None:
        found += label_deviations(labels, basis.parameters.get("forbidden_categories") or (),
                                  basis.parameters.get("safe_unknown_accepted") or ())
    offers = _offers(accepted, found)
    return [d if d.name not in offers else
            replace(d, given=offers[d.name],
                    accepted=value_matches(d.bound, offers[d.name]) or d.accepted_by is not None) for d in found]


__all__ = ["FORBIDDEN", "SAFE", "SYSTEM_CHOICES", "Deviation", "class_category", "colour_deviations", "deviations",
           "label_deviations", "value_matches", "value_text", "well_known_forbidden_colours"]
