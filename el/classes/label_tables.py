"""The plain-data tables of a label set and their checks (docs/architecture.md 2.1): classes, ignore colour, forms.

:class:`el.classes.labels.LabelSet` is built from these records; this module holds what does not need the
set itself, so that ``el/classes/labels.py`` stays one object. Two file forms are read here: the *class list*
(``classes: [{id, name, rgb, forbidden, hazard_score}]``, as ``LabelSet.to_dict`` writes it) and the
compact *palette* form a system file uses (``palette: {name: [r, g, b]}`` in id order, ``forbidden:
[names]``, ``hazard_scores: {name: score}``). Every problem is a ValueError naming the key and the value.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from el.classes.class_names import check_class_names
from el.classes.name_profile import profile_problem

MAX_CLASSES = 256  # class ids travel as uint8
CLASS_KEYS = ("id", "name", "rgb", "forbidden", "hazard_score", "category")
CATEGORIES = ("road", "vehicle", "building", "person", "animal", "water", "obstacle", "bare_ground", "vegetation",
              "tree", "marker", "unknown")
"""Hazard categories a class may declare (``category``): what the ground is, whatever the label set calls it. The
certification basis (``assurance.requirements.basis``) says which must be forbidden, and pins the category of the
well-known class names (``el.classes.class_names.PINNED_CATEGORIES``: a set cannot redeclare road's); road, vehicle and
building are the paper's hazards (avoid roads at all costs; do not land on cars or buildings), water the ground a
parachute cannot be recovered from; person and animal are listed so that a set's choice about them is visible."""
IGNORE_KEYS = ("rgb", "id", "counts_as", "name")
IGNORE_COUNTS_AS = ("forbidden", "excluded")
"""How the ground truth treats an ignored pixel: ``forbidden`` (default: unknown ground cannot be shown
safe, so a disc holding one is unsafe) or ``excluded`` (left out of the disc; a disc with no labelled
pixel is still unsafe)."""
DEFAULT_IGNORE_ID = 255


@dataclass(frozen=True)
class LabelClass:
    """One class: train id, name, label colour, EL category and hazard score."""

    id: int
    name: str
    rgb: tuple[int, int, int]
    forbidden: bool
    hazard_score: float | None  # s_l for safe classes, None for forbidden ones
    category: str | None = field(default=None, compare=False)  # hazard category (CATEGORIES); None: not declared
    # (not part of equality: a set read back without its categories still flies the same classes)


@dataclass(frozen=True)
class IgnoreLabel:
    """The "unlabelled" colour: pixels no class was given to, read as id ``id`` (outside the class ids).

    ``counts_as`` (:data:`IGNORE_COUNTS_AS`) says how the ground truth treats them; ``name`` is what
    reports call them. Checked against the classes by :class:`el.classes.labels.LabelSet`.
    """

    rgb: tuple[int, int, int]
    id: int = DEFAULT_IGNORE_ID
    counts_as: str = "forbidden"
    name: str = "unlabelled"

    def to_dict(self) -> dict[str, Any]:
        """Plain data; :func:`ignore_from_dict` gives an equal record back."""
        return {"rgb": [int(v) for v in self.rgb], "id": int(self.id), "counts_as": self.counts_as,
                "name": self.name}


def is_int(v: Any) -> bool:
    """An integer that is not a bool (numpy integers included)."""
    return isinstance(v, int | np.integer) and not isinstance(v, bool)


def _is_rgb(rgb: Any) -> bool:
    return not isinstance(rgb, str) and isinstance(rgb, Sequence) and len(rgb) == 3 \
        and all(is_int(v) and 0 <= v <= 255 for v in rgb)


def freeze(value: Any) -> Any:
    """A hashable, order-insensitive form of a hierarchy mapping (for equality and hashing)."""
    if isinstance(value, Mapping):
        return tuple(sorted((str(k), freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(freeze(v) for v in value)
    return value


def check_hierarchy_shape(hierarchy: Any) -> dict[str, Any]:
    """``{"root": NAME, "children": {parent: [children]}}`` as plain dicts and lists; ValueError otherwise.

    Only the shape: whether it is a tree over the set's classes is checked by the CH monitor's
    :class:`el.monitors.hierarchy.ClassHierarchy` (``LabelSet.from_dict`` builds one to check it).
    """
    if not isinstance(hierarchy, Mapping) or not isinstance(hierarchy.get("root"), str) \
            or not isinstance(hierarchy.get("children"), Mapping) or set(hierarchy) - {"root", "children"}:
        raise ValueError("hierarchy: needs 'root: NAME' and 'children: {parent: [children]}', nothing else")
    children: dict[str, list[str]] = {}
    for parent, kids in hierarchy["children"].items():
        if isinstance(kids, str) or not isinstance(kids, Sequence) or not all(isinstance(k, str) for k in kids):
            raise ValueError(f"hierarchy: children of {parent!r} must be a list of names, got {kids!r}")
        children[str(parent)] = list(kids)
    return {"root": hierarchy["root"], "children": children}


def check_hierarchy_covers(hierarchy: Mapping[str, Any], names: Sequence[str]) -> None:
    """Every class is a leaf of the hierarchy (its full check is the CH monitor's, when it is built:
    ``el.monitors.hierarchy.ClassHierarchy``; this module must not import it)."""
    children = hierarchy["children"]
    listed = {str(k) for kids in children.values() for k in kids}
    missing = [n for n in names if n not in listed]
    if missing:
        raise ValueError(f"hierarchy: classes missing from the hierarchy: {missing}")


def class_from_dict(i: int, c: Any) -> LabelClass:
    """One entry of the class-list form; ValueError naming the entry."""
    where = f"class #{i}"
    if not isinstance(c, Mapping):
        raise ValueError(f"{where} must be a mapping with keys {', '.join(CLASS_KEYS)}, got {c!r}")
    if isinstance(c.get("name"), str):
        where = f"class #{i} ({c['name']!r})"
    unknown = sorted(set(map(str, c)) - set(CLASS_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown keys {unknown} (allowed: {', '.join(CLASS_KEYS)})")
    missing = [k for k in ("id", "name", "rgb", "forbidden") if k not in c]
    if missing:
        raise ValueError(f"{where}: missing {', '.join(missing)}")
    if not is_int(c["id"]):
        raise ValueError(f"{where}: id must be an integer, got {c['id']!r}")
    rgb = c["rgb"]
    if isinstance(rgb, str) or not isinstance(rgb, Sequence):
        raise ValueError(f"{where}: rgb must be a list of 3 integers in 0..255, got {rgb!r}")
    return LabelClass(c["id"], c["name"], tuple(rgb), c["forbidden"], c.get("hazard_score"),  # type: ignore[arg-type]
                      c.get("category"))


def ignore_from_dict(d: Any) -> IgnoreLabel:
    """The ``ignore:`` entry (``{rgb: [r, g, b], id: 255, counts_as: forbidden, name: unlabelled}``, only
    ``rgb`` required); ValueError naming the key and the value."""
    if not isinstance(d, Mapping):
        raise ValueError(f"ignore: must be a mapping with keys {', '.join(IGNORE_KEYS)}, got {d!r}")
    unknown = sorted(set(map(str, d)) - set(IGNORE_KEYS))
    if unknown:
        raise ValueError(f"ignore: unknown keys {unknown} (allowed: {', '.join(IGNORE_KEYS)})")
    if "rgb" not in d:
        raise ValueError("ignore: needs rgb: [r, g, b]")
    rgb = d["rgb"]
    if not _is_rgb(rgb):
        raise ValueError(f"ignore.rgb: must be 3 integers in 0..255, got {rgb!r}")
    return IgnoreLabel(tuple(int(v) for v in rgb), d.get("id", DEFAULT_IGNORE_ID),  # type: ignore[arg-type]
                       d.get("counts_as", "forbidden"), d.get("name", "unlabelled"))


def validate_ignore(ignore: Any, classes: Sequence[LabelClass]) -> None:
    """ValueError naming the key and the value when the ignore record clashes with the classes."""
    if not isinstance(ignore, IgnoreLabel):
        raise ValueError(f"ignore: must be an IgnoreLabel record, got {ignore!r}")
    if not _is_rgb(ignore.rgb):
        raise ValueError(f"ignore.rgb: must be 3 integers in 0..255, got {ignore.rgb!r}")
    n = len(classes)
    if not is_int(ignore.id) or not n <= ignore.id <= MAX_CLASSES - 1:
        raise ValueError(f"ignore.id: must be an integer in {n}..{MAX_CLASSES - 1} (outside the class ids "
                         f"0..{n - 1}), got {ignore.id!r}")
    if ignore.counts_as not in IGNORE_COUNTS_AS:
        raise ValueError(f"ignore.counts_as: must be one of {', '.join(IGNORE_COUNTS_AS)}, got {ignore.counts_as!r}")
    if not isinstance(ignore.name, str) or not ignore.name.strip():
        raise ValueError(f"ignore.name: must be a non-empty string, got {ignore.name!r}")
    why = profile_problem(ignore.name)
    # reports name it beside the classes: held to the class names' profile (el.classes.name_profile)
    if why is not None:
        raise ValueError(f"ignore.name: {ignore.name!r} (written {ascii(ignore.name)}) is outside the class-name "
                         f"profile: {why}")
    rgb = tuple(int(v) for v in ignore.rgb)
    for c in classes:
        if tuple(int(v) for v in c.rgb) == rgb:
            raise ValueError(f"ignore.rgb: RGB{rgb} is already the colour of class {c.name!r}")
        if c.name == ignore.name:
            raise ValueError(f"ignore.name: {ignore.name!r} is already a class name")


def classes_from_palette(d: Mapping[str, Any]) -> list[LabelClass]:
    """The classes of the compact form: ``palette`` (name -> RGB, ids in order), ``forbidden`` (names),
    ``hazard_scores`` (safe name -> score). ValueError naming the key and the value."""
    palette, forbidden, scores = d.get("palette"), d.get("forbidden", []), d.get("hazard_scores", {})
    if not isinstance(palette, Mapping) or not palette:
        raise ValueError(f"palette: must be a non-empty mapping of class name -> [r, g, b], got {palette!r}")
    names = [str(k) for k in palette]
    seen: dict[tuple[int, ...], str] = {}
    for name, rgb in palette.items():
        if not _is_rgb(rgb):
            raise ValueError(f"palette.{name}: must be 3 integers in 0..255, got {rgb!r}")
        key = tuple(int(v) for v in rgb)
        if key in seen:
            raise ValueError(f"palette.{name}: RGB{key} is already the colour of {seen[key]!r}")
        seen[key] = str(name)
    if isinstance(forbidden, str) or not isinstance(forbidden, Sequence):
        raise ValueError(f"forbidden: must be a list of class names, got {forbidden!r}")
    for f in forbidden:
        if f not in names:
            raise ValueError(f"forbidden: {f!r} is not a class of the palette (classes: {', '.join(names)})")
    if not isinstance(scores, Mapping):
        raise ValueError(f"hazard_scores: must be a mapping of safe class name -> score, got {scores!r}")
    for k, v in scores.items():
        if k not in names:
            raise ValueError(f"hazard_scores.{k}: not a class of the palette (classes: {', '.join(names)})")
        if k in forbidden:
            raise ValueError(f"hazard_scores.{k}: {k!r} is forbidden and takes no score (got {v!r})")
    missing = [n for n in names if n not in forbidden and n not in scores]
    if missing:
        raise ValueError(f"hazard_scores: safe classes {missing} need a score (a number >= 0)")
    categories = d.get("categories") or {}
    if not isinstance(categories, Mapping) or any(k not in names for k in categories):
        raise ValueError(f"categories: must be a mapping of class name -> category, got {categories!r}")
    return [LabelClass(i, n, tuple(int(v) for v in palette[n]), n in forbidden,  # type: ignore[arg-type]
                       None if n in forbidden else scores[n], categories.get(n)) for i, n in enumerate(names)]


def validate_classes(set_name: str, classes: tuple[LabelClass, ...]) -> None:
    """ValueError naming the first problem of a class table (see :class:`el.classes.labels.LabelSet`)."""
    if not classes:
        raise ValueError(f"label set {set_name!r} has no classes")
    if len(classes) > MAX_CLASSES:
        raise ValueError(f"label set {set_name!r} has {len(classes)} classes, at most {MAX_CLASSES} are supported")
    for c in classes:
        _validate_class(set_name, c)
        if c.category is not None and c.category not in CATEGORIES:
            raise ValueError(f"label set {set_name!r}: class {c.name!r}: category {c.category!r} is not one of "
                             f"{', '.join(CATEGORIES)}")
    ids = [int(c.id) for c in classes]
    n = len(classes)
    if sorted(ids) != list(range(n)):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        missing = sorted(set(range(n)) - set(ids))
        outside = sorted(i for i in set(ids) if not 0 <= i < n)
        detail = "; ".join(p for p in (f"duplicate ids {dup}" if dup else "", f"missing ids {missing}" if missing
                                        else "", f"ids out of range {outside}" if outside else "") if p)
        raise ValueError(f"label set {set_name!r}: class ids must be 0..{n - 1}, each once ({detail})")
    if ids != list(range(n)):
        raise ValueError(f"label set {set_name!r}: classes must be listed in id order 0..{n - 1}, got {ids}")
    names = [c.name for c in classes]
    dup_names = sorted({x for x in names if names.count(x) > 1})
    if dup_names:
        raise ValueError(f"label set {set_name!r}: duplicate class names {dup_names}")
    check_class_names(set_name, names)  # no look-alike of a well-known name, no two classes that look alike
    colours = [tuple(int(v) for v in c.rgb) for c in classes]
    for k, rgb in enumerate(colours):
        first = colours.index(rgb)
        if first != k:
            raise ValueError(f"label set {set_name!r}: classes {names[first]!r} and {names[k]!r} share the "
                             f"colour RGB{rgb}")
    if not any(c.forbidden for c in classes):
        raise ValueError(f"label set {set_name!r} has no forbidden class (at least one is needed)")
    if all(c.forbidden for c in classes):
        raise ValueError(f"label set {set_name!r} has no safe class (at least one is needed)")


def _validate_class(set_name: str, c: Any) -> None:
    if not isinstance(c, LabelClass):
        raise ValueError(f"label set {set_name!r}: classes must be LabelClass records, got {c!r}")
    what = f"class {c.name!r}"
    if not isinstance(c.name, str) or not c.name.strip():
        raise ValueError(f"class with id {c.id!r}: name must be a non-empty string, got {c.name!r}")
    if not is_int(c.id):
        raise ValueError(f"{what}: id must be an integer, got {c.id!r}")
    if len(c.rgb) != 3 or not all(is_int(v) and 0 <= v <= 255 for v in c.rgb):
        raise ValueError(f"{what}: rgb must be 3 integers in 0..255, got {c.rgb!r}")
    if not isinstance(c.forbidden, bool | np.bool_):
        raise ValueError(f"{what}: forbidden must be true or false, got {c.forbidden!r}")
    if c.forbidden:
        if c.hazard_score is not None:
            raise ValueError(f"{what} is forbidden and must have no hazard score (it never lies in a "
                             f"landing disc), got {c.hazard_score!r}")
        return
    s = c.hazard_score
    if s is None:
        raise ValueError(f"safe {what} needs a hazard score (a number >= 0)")
    if isinstance(s, bool) or not isinstance(s, int | float | np.integer | np.floating) \
            or not math.isfinite(float(s)) or float(s) < 0:
        raise ValueError(f"safe {what}: hazard score must be a finite number >= 0, got {s!r}")
