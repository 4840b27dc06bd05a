"""Label sets: classes, their colours, emergency-landing categories and hazard scores (docs/architecture.md 2.1).

A :class:`LabelSet` is data: the code that needs class knowledge (the forbidden rule, the hazard
ranking, the monitors, the segmenter's shape checks) is handed one, so the policy lives in one
object. :data:`UAVID` is the shipped set, the eight UAVid classes, and the default wherever a set is
not given. A user's own set is a YAML or JSON file (:func:`load_label_set`)::

    name: fields
    classes:
      - {id: 0, name: grass, rgb: [0, 160, 0], forbidden: false, hazard_score: 0}
      - {id: 1, name: road, rgb: [128, 64, 128], forbidden: true}
    hierarchy:            # optional, for the CH monitor; default: any -> {safe, unsafe} -> classes
      root: any
      children: {any: [safe, unsafe], safe: [grass], unsafe: [road]}

The module-level names (:data:`CLASSES`, :data:`NUM_CLASSES`, ..., :func:`colors_to_ids`) are the
default set's, for code that is not handed a set.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from el.errors import LabelColourError

MAX_CLASSES = 256  # class ids travel as uint8
_CLASS_KEYS = ("id", "name", "rgb", "forbidden", "hazard_score")
_SET_KEYS = ("name", "classes", "hierarchy")


@dataclass(frozen=True)
class LabelClass:
    """One class: train id, name, label colour, EL category and hazard score."""

    id: int
    name: str
    rgb: tuple[int, int, int]
    forbidden: bool
    hazard_score: float | None  # s_l for safe classes, None for forbidden ones


UavidClass = LabelClass  # the name of the record when the UAVid classes were the only ones


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _pack(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.uint32, copy=False)
    return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]


def _freeze(value: Any) -> Any:
    """A hashable, order-insensitive form of a hierarchy mapping (for equality and hashing)."""
    if isinstance(value, Mapping):
        return tuple(sorted((str(k), _freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


def _check_hierarchy_shape(hierarchy: Any) -> dict[str, Any]:
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


@dataclass(frozen=True, eq=False)
class LabelSet:
    """A label set: named classes with colours, the forbidden/safe split and the safe classes' hazard scores.

    Parameters
    ----------
    name : str
        What the set is called (``"uavid"``); reports and model cards record it.
    classes : tuple of LabelClass
        ``classes[i].id == i``: ids 0..n-1 in order, unique names and colours, a finite hazard score
        >= 0 for every safe class and none for a forbidden one, at least one class of each kind.
    hierarchy : mapping, optional
        The CH monitor's class tree, ``{"root": NAME, "children": {parent: [children]}}`` with every
        class a leaf. None: the shipped ``hierarchy.yaml`` for :data:`UAVID`, else ``any -> {safe,
        unsafe} -> classes`` (``el.monitors.hierarchy.default_hierarchy``).

    Attributes (the default set's are the module-level names): ``num_classes``, ``names``, ``ids``
    (name -> id), ``forbidden_ids``, ``safe_ids``, ``palette`` (n, 3) uint8, ``forbidden_lut`` (n,)
    bool, ``hazard_scores`` (n,) float64 (0 for forbidden classes), ``max_hazard_score``. Arrays are
    read-only. Invalid tables raise ValueError naming the problem.

    Examples
    --------
    >>> s = LabelSet("toy", (LabelClass(0, "grass", (0, 160, 0), False, 0.0),
    ...                      LabelClass(1, "road", (128, 64, 128), True, None)))
    >>> s.forbidden_ids, s.safe_ids, s.num_classes
    ((1,), (0,), 2)
    >>> LabelSet.from_dict(s.to_dict()) == s
    True
    """

    name: str
    classes: tuple[LabelClass, ...]
    hierarchy: Mapping[str, Any] | None = None
    num_classes: int = field(init=False)
    names: tuple[str, ...] = field(init=False)
    ids: dict[str, int] = field(init=False, repr=False)
    forbidden_ids: tuple[int, ...] = field(init=False, repr=False)
    safe_ids: tuple[int, ...] = field(init=False, repr=False)
    palette: np.ndarray = field(init=False, repr=False)
    forbidden_lut: np.ndarray = field(init=False, repr=False)
    hazard_scores: np.ndarray = field(init=False, repr=False)
    max_hazard_score: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"label set name must be a non-empty string, got {self.name!r}")
        classes = tuple(self.classes)
        object.__setattr__(self, "classes", classes)
        _validate_classes(self.name, classes)
        if self.hierarchy is not None:
            object.__setattr__(self, "hierarchy", _check_hierarchy_shape(self.hierarchy))
        hazard = np.array([c.hazard_score or 0.0 for c in classes], dtype=np.float64)
        # Hazard score per class; forbidden classes get 0 because they never lie in a valid disc.
        derived = {
            "num_classes": len(classes),
            "names": tuple(c.name for c in classes),
            "ids": {c.name: c.id for c in classes},
            "forbidden_ids": tuple(c.id for c in classes if c.forbidden),
            "safe_ids": tuple(c.id for c in classes if not c.forbidden),
            "palette": _readonly(np.array([c.rgb for c in classes], dtype=np.uint8)),  # row = class id
            "forbidden_lut": _readonly(np.array([c.forbidden for c in classes], dtype=bool)),
            "hazard_scores": _readonly(hazard),
            "max_hazard_score": float(hazard.max()),
        }
        for k, v in derived.items():
            object.__setattr__(self, k, v)
        keys = _pack(self.palette)
        order = np.argsort(keys)
        object.__setattr__(self, "_order", _readonly(order))
        object.__setattr__(self, "_sorted_keys", _readonly(keys[order]))

    # -- identity ------------------------------------------------------------------------------
    def _key(self) -> tuple[Any, ...]:
        return self.name, self.classes, _freeze(self.hierarchy)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LabelSet):
            return NotImplemented
        return self is other or self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return f"LabelSet({self.name!r}, {self.num_classes} classes: {', '.join(self.names)})"

    # -- conversions ---------------------------------------------------------------------------
    def colors_to_ids(self, rgb: np.ndarray, source: str | Path = "<array>") -> np.ndarray:
        """Map an RGB label image (H, W, 3) uint8 to class ids (H, W) uint8.

        Raises LabelColourError naming ``source``, the unknown colours and their pixel counts:
        a colour outside the table is never silently mapped to a class.
        """
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise LabelColourError(f"{source}: label image must be (H, W, 3) RGB, got shape {rgb.shape}")
        sorted_keys: np.ndarray = self._sorted_keys  # type: ignore[attr-defined]
        keys = _pack(rgb)
        pos = np.searchsorted(sorted_keys, keys)
        pos = np.clip(pos, 0, len(sorted_keys) - 1)
        known = sorted_keys[pos] == keys
        if not known.all():
            bad, counts = np.unique(keys[~known], return_counts=True)
            order = np.argsort(-counts)[:5]
            parts = [
                f"RGB({(int(k) >> 16) & 255},{(int(k) >> 8) & 255},{int(k) & 255}) x {int(c)} px"
                for k, c in zip(bad[order], counts[order], strict=True)
            ]
            more = f" and {len(bad) - 5} more colours" if len(bad) > 5 else ""
            raise LabelColourError(
                f"{source}: {int((~known).sum())} pixels have colours that are not {self._title} classes: "
                + ", ".join(parts)
                + more
            )
        return self._order[pos].astype(np.uint8)  # type: ignore[attr-defined]

    @property
    def _title(self) -> str:
        return "UAVid" if self.name == "uavid" else f"{self.name!r}"

    def ids_to_colors(self, ids: np.ndarray) -> np.ndarray:
        """Map class ids (H, W) to the RGB label image (H, W, 3) uint8."""
        ids = np.asarray(ids)
        n = self.num_classes
        if ids.size and (ids.min() < 0 or ids.max() >= n):
            raise ValueError(f"class ids must lie in 0..{n - 1}, got {ids.min()}..{ids.max()}")
        return self.palette[ids]

    def forbidden_mask(self, ids: np.ndarray) -> np.ndarray:
        """True where the class id is a forbidden class."""
        return self.forbidden_lut[np.asarray(ids)]

    # -- files ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON/YAML-ready); :meth:`from_dict` gives an equal set back."""
        out: dict[str, Any] = {
            "name": self.name,
            "classes": [
                {"id": c.id, "name": c.name, "rgb": [int(v) for v in c.rgb], "forbidden": bool(c.forbidden),
                 **({} if c.forbidden else {"hazard_score": float(c.hazard_score)})}  # type: ignore[arg-type]
                for c in self.classes
            ],
        }
        if self.hierarchy is not None:
            out["hierarchy"] = json.loads(json.dumps(self.hierarchy))
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LabelSet:
        """A label set from :meth:`to_dict`'s form, checked: ValueError naming the first problem.

        ``classes`` may list the classes in any order (they are sorted by id); a forbidden class has
        no ``hazard_score`` (or null). A ``hierarchy`` is checked to be a tree over the classes.
        """
        if not isinstance(d, Mapping):
            raise ValueError(f"a label set must be a mapping, got {type(d).__name__}")
        unknown = sorted(set(map(str, d)) - set(_SET_KEYS))
        if unknown:
            raise ValueError(f"unknown label set keys {unknown} (allowed: {', '.join(_SET_KEYS)})")
        if "name" not in d or "classes" not in d:
            raise ValueError("a label set needs 'name' and 'classes'")
        name = d["name"]
        if not isinstance(name, str):
            raise ValueError(f"label set name must be a string, got {name!r}")
        raw = d["classes"]
        if isinstance(raw, str | bytes | Mapping) or not isinstance(raw, Sequence):
            raise ValueError(f"'classes' must be a list of classes, got {type(raw).__name__}")
        classes = [_class_from_dict(i, c) for i, c in enumerate(raw)]
        labels = cls(name, tuple(sorted(classes, key=lambda c: c.id)), d.get("hierarchy"))
        if labels.hierarchy is not None:
            _check_hierarchy_covers(labels.hierarchy, labels.names)
        return labels


def _check_hierarchy_covers(hierarchy: Mapping[str, Any], names: Sequence[str]) -> None:
    """Every class is a leaf of the hierarchy (its full check is the CH monitor's, when it is built:
    ``el.monitors.hierarchy.ClassHierarchy``; this module must not import it, which imports this one)."""
    children = hierarchy["children"]
    listed = {str(k) for kids in children.values() for k in kids}
    missing = [n for n in names if n not in listed]
    if missing:
        raise ValueError(f"hierarchy: classes missing from the hierarchy: {missing}")


def _class_from_dict(i: int, c: Any) -> LabelClass:
    where = f"class #{i}"
    if not isinstance(c, Mapping):
        raise ValueError(f"{where} must be a mapping with keys {', '.join(_CLASS_KEYS)}, got {c!r}")
    if isinstance(c.get("name"), str):
        where = f"class #{i} ({c['name']!r})"
    unknown = sorted(set(map(str, c)) - set(_CLASS_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown keys {unknown} (allowed: {', '.join(_CLASS_KEYS)})")
    missing = [k for k in ("id", "name", "rgb", "forbidden") if k not in c]
    if missing:
        raise ValueError(f"{where}: missing {', '.join(missing)}")
    if not _is_int(c["id"]):
        raise ValueError(f"{where}: id must be an integer, got {c['id']!r}")
    rgb = c["rgb"]
    if isinstance(rgb, str) or not isinstance(rgb, Sequence):
        raise ValueError(f"{where}: rgb must be a list of 3 integers in 0..255, got {rgb!r}")
    return LabelClass(c["id"], c["name"], tuple(rgb), c["forbidden"], c.get("hazard_score"))  # type: ignore[arg-type]


def _is_int(v: Any) -> bool:
    return isinstance(v, int | np.integer) and not isinstance(v, bool)


def _validate_classes(set_name: str, classes: tuple[LabelClass, ...]) -> None:
    """ValueError naming the first problem of a class table (see :class:`LabelSet`)."""
    if not classes:
        raise ValueError(f"label set {set_name!r} has no classes")
    if len(classes) > MAX_CLASSES:
        raise ValueError(f"label set {set_name!r} has {len(classes)} classes, at most {MAX_CLASSES} are supported")
    for c in classes:
        if not isinstance(c, LabelClass):
            raise ValueError(f"label set {set_name!r}: classes must be LabelClass records, got {c!r}")
        what = f"class {c.name!r}"
        if not isinstance(c.name, str) or not c.name.strip():
            raise ValueError(f"class with id {c.id!r}: name must be a non-empty string, got {c.name!r}")
        if not _is_int(c.id):
            raise ValueError(f"{what}: id must be an integer, got {c.id!r}")
        if len(c.rgb) != 3 or not all(_is_int(v) and 0 <= v <= 255 for v in c.rgb):
            raise ValueError(f"{what}: rgb must be 3 integers in 0..255, got {c.rgb!r}")
        if not isinstance(c.forbidden, bool | np.bool_):
            raise ValueError(f"{what}: forbidden must be true or false, got {c.forbidden!r}")
        if c.forbidden:
            if c.hazard_score is not None:
                raise ValueError(f"{what} is forbidden and must have no hazard score (it never lies in a "
                                 f"landing disc), got {c.hazard_score!r}")
        else:
            s = c.hazard_score
            if s is None:
                raise ValueError(f"safe {what} needs a hazard score (a number >= 0)")
            if isinstance(s, bool) or not isinstance(s, int | float | np.integer | np.floating) \
                    or not math.isfinite(float(s)) or float(s) < 0:
                raise ValueError(f"safe {what}: hazard score must be a finite number >= 0, got {s!r}")
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


def load_label_set(path: str | Path) -> LabelSet:
    """A label set from a YAML (``.yaml``/``.yml``) or JSON file in :meth:`LabelSet.to_dict`'s form.

    ``hierarchy`` may be a mapping or the name of a hierarchy YAML file (``root:`` and ``children:``,
    as ``el/monitors/hierarchy.yaml``), relative to the label set file. ValueError naming the file.
    """
    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as err:
        raise ValueError(f"{p}: cannot read label set ({err.strerror or err})") from None
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as err:
        raise ValueError(f"{p}: not valid {'JSON' if p.suffix.lower() == '.json' else 'YAML'}: {err}") from None
    try:
        if isinstance(data, dict) and isinstance(data.get("hierarchy"), str):
            ref = p.parent / data["hierarchy"]
            try:
                data = {**data, "hierarchy": yaml.safe_load(ref.read_text(encoding="utf-8"))}
            except (OSError, yaml.YAMLError) as err:
                raise ValueError(f"hierarchy file {ref}: {err}") from None
        return LabelSet.from_dict(data)
    except ValueError as err:
        raise ValueError(f"{p}: {err}") from None


# -- the default set: UAVid ------------------------------------------------------------------------
CLASSES: tuple[LabelClass, ...] = (
    LabelClass(0, "clutter", (0, 0, 0), False, 2.0),
    LabelClass(1, "building", (128, 0, 0), True, None),
    LabelClass(2, "road", (128, 64, 128), True, None),
    LabelClass(3, "static_car", (192, 0, 192), True, None),
    LabelClass(4, "tree", (0, 128, 0), False, 3.0),
    LabelClass(5, "low_vegetation", (128, 128, 0), False, 0.0),
    LabelClass(6, "human", (64, 64, 0), False, 1.0),
    LabelClass(7, "moving_car", (64, 0, 128), True, None),
)

UAVID = LabelSet("uavid", CLASSES)
"""The UAVid label set (docs/architecture.md 2.1): the default wherever a set is not given."""

# The default set's values, for code that is not handed a set.
NUM_CLASSES = UAVID.num_classes
CLASS_NAMES: tuple[str, ...] = UAVID.names
CLASS_IDS: dict[str, int] = UAVID.ids
FORBIDDEN_IDS: tuple[int, ...] = UAVID.forbidden_ids
SAFE_IDS: tuple[int, ...] = UAVID.safe_ids
PALETTE = UAVID.palette  # (8, 3), row = class id
FORBIDDEN_LUT = UAVID.forbidden_lut
HAZARD_SCORES = UAVID.hazard_scores  # 0 for forbidden classes
MAX_HAZARD_SCORE = UAVID.max_hazard_score


def colors_to_ids(rgb: np.ndarray, source: str | Path = "<array>") -> np.ndarray:
    """The default set's :meth:`LabelSet.colors_to_ids`: RGB label image (H, W, 3) -> class ids (H, W) uint8."""
    return UAVID.colors_to_ids(rgb, source)


def ids_to_colors(ids: np.ndarray) -> np.ndarray:
    """The default set's :meth:`LabelSet.ids_to_colors`: class ids (H, W) -> RGB label image (H, W, 3) uint8."""
    return UAVID.ids_to_colors(ids)


def forbidden_mask(ids: np.ndarray) -> np.ndarray:
    """The default set's :meth:`LabelSet.forbidden_mask`: True where the class is forbidden (building, road,
    static or moving car)."""
    return UAVID.forbidden_mask(ids)
