"""Label sets: classes, their colours, emergency-landing categories and hazard scores (docs/architecture.md 2.1).

A :class:`LabelSet` is data: the code that needs class knowledge (the forbidden rule, the hazard
ranking, the monitors, the segmenter's shape checks) is handed one, so the policy lives in one
object. :data:`UAVID` is the shipped set, the eight UAVid classes, and the default wherever a set is
not given. A user's own set is a YAML or JSON file (:func:`load_label_set`)::

    name: fields
    classes:
      - {id: 0, name: grass, rgb: [0, 160, 0], forbidden: false, hazard_score: 0}
      - {id: 1, name: road, rgb: [128, 64, 128], forbidden: true}
    ignore: {rgb: [0, 0, 0], id: 255, counts_as: forbidden}   # optional "unlabelled" colour
    hierarchy:            # optional, for the CH monitor; default: any -> {safe, unsafe} -> classes
      root: any
      children: {any: [safe, unsafe], safe: [grass], unsafe: [road]}

or in the compact form a system file uses (``palette`` in id order, ``forbidden``, ``hazard_scores``).
Packaged sets load by name (``load_label_set("semantic_drone")``; ``el/data/labels/``). An ignored
pixel is unknown ground: the ground truth counts it as forbidden unless the set says ``counts_as: excluded``.

The module-level names (:data:`CLASSES`, :data:`NUM_CLASSES`, ..., :func:`colors_to_ids`) are the
default set's, for code that is not handed a set.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from el.base import safeyaml, userfiles
from el.base.errors import LabelColourError
from el.classes.label_tables import (  # noqa: F401  (LabelClass, IgnoreLabel, MAX_CLASSES re-exported: part of the seam)
    IGNORE_COUNTS_AS,
    MAX_CLASSES,
    IgnoreLabel,
    LabelClass,
    check_hierarchy_covers,
    check_hierarchy_shape,
    class_from_dict,
    classes_from_palette,
    freeze,
    ignore_from_dict,
    validate_classes,
    validate_ignore,
)

UavidClass = LabelClass  # the name of the record when the UAVid classes were the only ones
_SET_KEYS = ("name", "classes", "palette", "forbidden", "hazard_scores", "categories", "ignore", "hierarchy")
PRESET_DIR = Path(__file__).resolve().parents[1] / "data" / "labels"
"""The packaged label sets (``NAME.yaml``), loaded by name with :func:`load_label_set`."""


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _pack(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.uint32, copy=False)
    return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]


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
    ignore : IgnoreLabel, optional
        The "unlabelled" colour: :meth:`colors_to_ids` reads it as ``ignore.id`` (outside 0..n-1) instead
        of refusing it, :meth:`ids_to_colors` writes it back, and the ground truth counts such a pixel
        as forbidden unless ``ignore.counts_as == "excluded"`` (:meth:`forbidden_mask`,
        ``assurance.campaign.truth.true_hazard``). None: every pixel must carry a class colour.

    Attributes (the default set's are the module-level names): ``num_classes``, ``names``, ``ids``
    (name -> id), ``forbidden_ids``, ``safe_ids``, ``palette`` (n, 3) uint8, ``forbidden_lut`` (n,)
    bool, ``hazard_scores`` (n,) float64 (0 for forbidden classes), ``max_hazard_score``. Arrays are
    read-only. Invalid tables raise ValueError naming the problem.

    Examples
    --------
    >>> s = LabelSet("toy", (LabelClass(0, "grass", (0, 160, 0), False, 0.0),
    ...                      LabelClass(1, "road", (128, 64, 128), True, None, "road")))
    >>> s.forbidden_ids, s.safe_ids, s.num_classes
    ((1,), (0,), 2)
    >>> LabelSet.from_dict(s.to_dict()) == s
    True
    """

    name: str
    classes: tuple[LabelClass, ...]
    hierarchy: Mapping[str, Any] | None = None
    ignore: IgnoreLabel | None = None
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
        validate_classes(self.name, classes)
        if self.hierarchy is not None:
            object.__setattr__(self, "hierarchy", check_hierarchy_shape(self.hierarchy))
        if self.ignore is not None:
            validate_ignore(self.ignore, classes)
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
        colours, values = self.palette, np.arange(len(classes))
        colour_lut = np.zeros((MAX_CLASSES, 3), np.uint8)  # id -> colour, for ids_to_colors
        colour_lut[: len(classes)] = self.palette
        if self.ignore is not None:
            colours = np.vstack([colours, np.array([self.ignore.rgb], np.uint8)])
            values = np.append(values, int(self.ignore.id))
            colour_lut[int(self.ignore.id)] = self.ignore.rgb
        keys = _pack(colours)
        order = np.argsort(keys)
        truth = np.zeros(MAX_CLASSES, bool)  # id -> counts as forbidden ground (ignore id included)
        truth[: len(classes)] = self.forbidden_lut
        if self.ignore is not None:
            truth[int(self.ignore.id)] = self.ignore.counts_as == "forbidden"
        object.__setattr__(self, "_values", _readonly(values[order].astype(np.uint8)))
        object.__setattr__(self, "_sorted_keys", _readonly(keys[order]))
        object.__setattr__(self, "_colour_lut", _readonly(colour_lut))
        object.__setattr__(self, "_truth_lut", _readonly(truth))

    # -- identity ------------------------------------------------------------------------------
    def _key(self) -> tuple[Any, ...]:
        return self.name, self.classes, freeze(self.hierarchy), self.ignore

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
        return self._values[pos]  # type: ignore[attr-defined]

    @property
    def _title(self) -> str:
        return "UAVid" if self.name == "uavid" else f"{self.name!r}"

    @property
    def ignore_id(self) -> int | None:
        """The id an ignored ("unlabelled") pixel reads as; None when the set has no ignore colour."""
        return None if self.ignore is None else int(self.ignore.id)

    def _check_ids(self, ids: np.ndarray) -> np.ndarray:
        ids = np.asarray(ids)
        if not ids.size:
            return ids
        n = self.num_classes
        if not np.issubdtype(ids.dtype, np.integer):
            raise ValueError(f"class ids must be integers, got {ids.dtype}")
        lo, hi = int(ids.min()), int(ids.max())
        if lo < 0 or hi >= n:
            outside = ids[(ids < 0) | (ids >= n)]
            if self.ignore is None or lo < 0 or (outside != self.ignore.id).any():
                extra = "" if self.ignore is None else f" or the ignore id {self.ignore.id}"
                raise ValueError(f"class ids must lie in 0..{n - 1}{extra}, got {lo}..{hi}")
        return ids

    def ids_to_colors(self, ids: np.ndarray) -> np.ndarray:
        """Map class ids (H, W) (and the ignore id, when the set has one) to the RGB label image (H, W, 3) uint8."""
        return self._colour_lut[self._check_ids(ids)]  # type: ignore[attr-defined]

    def forbidden_mask(self, ids: np.ndarray) -> np.ndarray:
        """True where the ground is forbidden: a forbidden class, or an ignored pixel unless the set's
        ``ignore.counts_as`` is ``"excluded"`` (then see :meth:`ignored_mask`)."""
        return self._truth_lut[self._check_ids(ids)]  # type: ignore[attr-defined]

    def ignored_mask(self, ids: np.ndarray) -> np.ndarray:
        """True where the pixel is ignored ("unlabelled"); all False for a set without an ignore colour."""
        ids = np.asarray(ids)
        return np.zeros(ids.shape, bool) if self.ignore is None else ids == self.ignore.id

    def planning_ids(self, ids: np.ndarray) -> np.ndarray:
        """Class ids 0..n-1 for code that plans on labels (``el.landing.core.probs_from_labels``): an ignored pixel
        becomes the first forbidden class, whatever ``counts_as`` says, since unknown ground is never a
        landing site. The ids themselves when nothing is ignored."""
        ids = self._check_ids(ids)
        if self.ignore is None or not (ids == self.ignore.id).any():
            return ids
        return np.where(ids == self.ignore.id, self.forbidden_ids[0], ids).astype(ids.dtype)

    def with_ignore(self, rgb: tuple[int, int, int] | Sequence[int], *, ignore_id: int = 255,
                    counts_as: str = "forbidden", name: str = "unlabelled") -> LabelSet:
        """This set with an ignore colour (replacing any it had); ValueError naming the key and the value."""
        if isinstance(rgb, str) or not isinstance(rgb, Sequence) or len(rgb) != 3:
            raise ValueError(f"ignore.rgb: must be 3 integers in 0..255, got {rgb!r}")
        return LabelSet(self.name, self.classes, self.hierarchy,
                        IgnoreLabel(tuple(rgb), ignore_id, counts_as, name))  # type: ignore[arg-type]

    def class_by_name(self, name: str) -> LabelClass:
        """The class called ``name``; ValueError naming it and the set's classes."""
        if name not in self.ids:
            raise ValueError(f"{name!r} is not a class of label set {self.name!r} (classes: {', '.join(self.names)})")
        return self.classes[self.ids[name]]

    # -- files ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON/YAML-ready); :meth:`from_dict` gives an equal set back."""
        out: dict[str, Any] = {
            "name": self.name,
            "classes": [
                {"id": c.id, "name": c.name, "rgb": [int(v) for v in c.rgb], "forbidden": bool(c.forbidden),
                 **({} if c.forbidden else {"hazard_score": float(c.hazard_score)}),  # type: ignore[arg-type]
                 **({} if c.category is None else {"category": c.category})}
                for c in self.classes
            ],
        }
        if self.ignore is not None:
            out["ignore"] = self.ignore.to_dict()
        if self.hierarchy is not None:
            out["hierarchy"] = json.loads(json.dumps(self.hierarchy))
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LabelSet:
        """A label set from :meth:`to_dict`'s form or the compact palette form, checked: ValueError naming
        the first problem (the key and the value).

        Class-list form: ``classes`` may list the classes in any order (they are sorted by id); a
        forbidden class has no ``hazard_score`` (or null). Palette form: ``palette`` (name -> RGB, ids
        in order), ``forbidden`` (names), ``hazard_scores`` (safe name -> score). Either may add
        ``ignore`` (``{rgb, id, counts_as, name}``) and a ``hierarchy`` (checked to be a tree over the classes).
        """
        if not isinstance(d, Mapping):
            raise ValueError(f"a label set must be a mapping, got {type(d).__name__}")
        unknown = sorted(set(map(str, d)) - set(_SET_KEYS))
        if unknown:
            raise ValueError(f"unknown label set keys {unknown} (allowed: {', '.join(_SET_KEYS)})")
        if "name" not in d or ("classes" in d) == ("palette" in d):
            raise ValueError("a label set needs 'name' and 'classes' (a list), or 'name' and 'palette' "
                             "(name -> RGB; the compact form), not both")
        name = d["name"]
        if not isinstance(name, str):
            raise ValueError(f"label set name must be a string, got {name!r}")
        if "palette" in d:
            classes = classes_from_palette(d)
        else:
            extra = sorted(k for k in ("forbidden", "hazard_scores", "categories") if k in d)
            if extra:
                raise ValueError(f"{', '.join(extra)}: belong to the palette form; with 'classes' each class says it")
            raw = d["classes"]
            if isinstance(raw, str | bytes | Mapping) or not isinstance(raw, Sequence):
                raise ValueError(f"'classes' must be a list of classes, got {type(raw).__name__}")
            classes = [class_from_dict(i, c) for i, c in enumerate(raw)]
        ignore = None if d.get("ignore") is None else ignore_from_dict(d["ignore"])
        labels = cls(name, tuple(sorted(classes, key=lambda c: c.id)), d.get("hierarchy"), ignore)
        if labels.hierarchy is not None:
            check_hierarchy_covers(labels.hierarchy, labels.names)
        return labels


def label_presets() -> tuple[str, ...]:
    """Names of the packaged label sets (``el/data/labels/NAME.yaml``), for :func:`load_label_set`."""
    return tuple(sorted(p.stem for p in PRESET_DIR.glob("*.yaml")))


def load_label_set(source: str | Path) -> LabelSet:
    """A label set by preset name (:func:`label_presets`: ``uavid``, ``semantic_drone``, ...) or from a YAML
    (``.yaml``/``.yml``) or JSON file in :meth:`LabelSet.from_dict`'s forms.

    ``"uavid"`` is :data:`UAVID` itself (its file, ``el/data/labels/uavid.yaml``, is checked equal to it by
    the tests). A value with one of those suffixes is a path; anything else must be a preset name.
    ``hierarchy`` may be a mapping or the name of a hierarchy YAML file (``root:`` and ``children:``,
    as ``el/monitors/hierarchy.yaml``), relative to the label set file. ValueError naming the file.
    """
    import yaml

    p = Path(source)
    if p.suffix.lower() not in (".yaml", ".yml", ".json"):
        presets = label_presets()
        if str(source) not in presets:
            raise ValueError(f"{str(source)!r} is neither a label set preset ({', '.join(presets)}) nor a "
                             ".yaml/.yml/.json file")
        if str(source) == "uavid":
            return UAVID
        p = PRESET_DIR / f"{source}.yaml"
    # a regular file of at most 1 MiB (a FIFO or /dev/zero refused before any read), nested at most 32 deep
    text = userfiles.read_text(p, what="label set file", max_bytes=safeyaml.MAX_YAML_BYTES)
    try:
        data = userfiles.parse_bounded(json.loads, text, where=str(p)) if p.suffix.lower() == ".json" \
            else safeyaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as err:
        raise ValueError(f"{p}: not valid {'JSON' if p.suffix.lower() == '.json' else 'YAML'}: {err}") from None
    try:
        if isinstance(data, dict) and isinstance(data.get("hierarchy"), str):
            ref = p.parent / data["hierarchy"]
            try:  # beside the label set: a name (or a link) leading out of its folder is refused
                data = {**data, "hierarchy": safeyaml.load_file(ref, what="hierarchy file", within=p.parent)}
            except (OSError, yaml.YAMLError) as err:
                raise ValueError(f"hierarchy file {ref}: {err}") from None
        return LabelSet.from_dict(data)
    except ValueError as err:
        raise ValueError(f"{p}: {err}") from None


# -- the default set: UAVid ------------------------------------------------------------------------
CLASSES: tuple[LabelClass, ...] = (
    LabelClass(0, "clutter", (0, 0, 0), False, 2.0, "unknown"),
    LabelClass(1, "building", (128, 0, 0), True, None, "building"),
    LabelClass(2, "road", (128, 64, 128), True, None, "road"),
    LabelClass(3, "static_car", (192, 0, 192), True, None, "vehicle"),
    LabelClass(4, "tree", (0, 128, 0), False, 3.0, "tree"),
    LabelClass(5, "low_vegetation", (128, 128, 0), False, 0.0, "vegetation"),
    LabelClass(6, "human", (64, 64, 0), False, 1.0, "person"),
    LabelClass(7, "moving_car", (64, 0, 128), True, None, "vehicle"),
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
