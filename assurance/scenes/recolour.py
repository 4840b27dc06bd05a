"""Rewrite a UAVid-layout data set's label PNGs into another palette (docs/architecture.md section 2.1).

``recolour_dataset(src, dst, source_labels, target_labels, mapping)`` copies ``src`` to ``dst``
(images, ``meta/`` and every other file unchanged, byte for byte) and rewrites each
``seqNN/Labels/*.png`` from ``source_labels``' palette into ``target_labels``': each source class goes to
the target class the mapping names (many-to-one allowed), an ignored pixel to the target's ignore colour.
It is how a data set labelled in one palette is made to look like one labelled in another (worked
example 2: the synthetic scenes in a foreign palette). A forbidden source class mapped onto a safe
target class would turn unsafe ground safe in the ground truth: refused unless ``allow_unsafe``.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from assurance.dataio.layouts import iter_samples, read_sample_labels, write_label_file
from assurance.dataio.uavid import LABEL_DIR
from assurance.files import atomic_write_bytes
from el.base.errors import DataError
from el.classes.labels import MAX_CLASSES, LabelSet


def class_lut(source_labels: LabelSet, target_labels: LabelSet, mapping: Mapping[str, str] | None = None, *,
              allow_unsafe: bool = False) -> np.ndarray:
    """(256,) uint8: the target id of each source id (the source's ignore id -> the target's).

    ``mapping``: source class name -> target class name or the target's ignore name; None maps each
    class onto the target class of the same name. Every source class must be mapped. ValueError naming
    the class for an unmapped or unknown class, or a forbidden class mapped onto a safe one (unless
    ``allow_unsafe``).
    """
    mapping = {n: n for n in source_labels.names} if mapping is None else dict(mapping)
    unknown = [k for k in mapping if k not in source_labels.ids]
    if unknown:
        raise ValueError(f"recolour: {unknown[0]!r} is not a class of the source label set {source_labels.name!r} "
                         f"(classes: {', '.join(source_labels.names)})")
    ignore_name = None if target_labels.ignore is None else target_labels.ignore.name
    lut = np.zeros(MAX_CLASSES, np.uint8)
    for c in source_labels.classes:
        if c.name not in mapping:
            raise ValueError(f"recolour: source class {c.name!r} is not mapped onto a class of "
                             f"{target_labels.name!r} (classes: {', '.join(target_labels.names)})")
        to = mapping[c.name]
        if to == ignore_name and target_labels.ignore is not None:
            lut[c.id] = target_labels.ignore.id
            continue
        if to not in target_labels.ids:
            raise ValueError(f"recolour: {c.name!r} -> {to!r}: not a class of the target label set "
                             f"{target_labels.name!r} (classes: {', '.join(target_labels.names)})")
        target = target_labels.classes[target_labels.ids[to]]
        if c.forbidden and not target.forbidden and not allow_unsafe:
            raise ValueError(f"recolour: forbidden class {c.name!r} -> safe class {to!r} would make unsafe ground "
                             "safe in the ground truth (pass allow_unsafe to do it anyway)")
        lut[c.id] = target.id
    if source_labels.ignore is not None:
        if target_labels.ignore is None:
            lut[source_labels.ignore.id] = 0  # checked per file: an ignored pixel needs an ignore colour
        else:
            lut[source_labels.ignore.id] = target_labels.ignore.id
    return lut


def recolour_labels(ids: np.ndarray, lut: np.ndarray, source_labels: LabelSet, target_labels: LabelSet,
                    source: str | Path = "<array>") -> np.ndarray:
    """Source class ids (H, W) -> target class ids through ``lut`` (:func:`class_lut`); DataError naming
    ``source`` when it has ignored pixels and the target set has no ignore colour."""
    if source_labels.ignore is not None and target_labels.ignore is None:
        n = int(source_labels.ignored_mask(ids).sum())
        if n:
            raise DataError(f"{source}: {n} ignored pixels ({source_labels.ignore.name}) and the target label set "
                            f"{target_labels.name!r} has no ignore colour")
    return lut[np.asarray(ids)]


def recolour_dataset(src: str | Path, dst: str | Path, source_labels: LabelSet, target_labels: LabelSet,
                     mapping: Mapping[str, str] | None = None, *, allow_unsafe: bool = False) -> dict[str, Any]:
    """Copy the UAVid-layout data set ``src`` to ``dst`` with its label PNGs in ``target_labels``' palette.

    Images and other files are copied unchanged, scene meta with its class shares named in the target's classes
    (:func:`_rename_shares`); ``dst`` must not exist or be empty. Returns
    ``{"labels": files rewritten, "pixels": {target class name: pixel count}}``. DataError (naming the
    file) for a label colour ``source_labels`` does not know; ValueError for a bad mapping (:func:`class_lut`).
    """
    src, dst = Path(src), Path(dst)
    lut = class_lut(source_labels, target_labels, mapping, allow_unsafe=allow_unsafe)
    samples = [s for s in iter_samples(src, require_labels=False) if s.label_path is not None]
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise DataError(f"{dst}: exists and is not an empty folder (recolour writes a new data set)")

    def skip_labels(folder: str, names: list[str]) -> list[str]:
        return [n for n in names if Path(folder).name == LABEL_DIR and n.lower().endswith(".png")]

    shutil.copytree(src, dst, ignore=skip_labels, dirs_exist_ok=True)
    target_names = {c.id: c.name for c in target_labels.classes}  # the ignore colour has none: its shares go
    renamed = {c.name: target_names.get(int(lut[c.id])) for c in source_labels.classes}
    for meta in sorted(dst.rglob("meta/*.json")):
        _rename_shares(meta, renamed)
    counts = np.zeros(MAX_CLASSES, np.int64)
    for s in samples:
        assert s.label_path is not None
        out = recolour_labels(read_sample_labels(s, source_labels), lut, source_labels, target_labels,
                              s.label_path)
        counts += np.bincount(out.ravel(), minlength=MAX_CLASSES)
        write_label_file(dst / s.label_path.relative_to(src), out, target_labels, encoding=s.label_encoding,
                         id_offset=s.id_offset)  # in the source's own encoding
    names = {**target_names,
             **({} if target_labels.ignore is None else {target_labels.ignore.id: target_labels.ignore.name})}
    return {"labels": len(samples), "pixels": {names[i]: int(counts[i]) for i in np.flatnonzero(counts)}}


def _rename_shares(path: Path, renamed: Mapping[str, str | None]) -> None:
    """A scene meta file's ``class_shares`` under the target's class names (shares of classes mapped onto one added,
    a class mapped onto the ignore colour dropped), so the report's class balance names the data's own classes; a
    file that is not such a record is left as it is."""
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return
    shares = meta.get("class_shares") if isinstance(meta, dict) else None
    if not isinstance(shares, dict):
        return
    out: dict[str, float] = {}
    for name, share in shares.items():
        to = renamed.get(str(name))
        if to is not None and isinstance(share, int | float):
            out[to] = out.get(to, 0.0) + float(share)
    atomic_write_bytes(path, (json.dumps({**meta, "class_shares": out}, separators=(",", ":")) + "\n").encode())
