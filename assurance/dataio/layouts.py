"""Data sets as users hold them: one data source for every layout (docs/system-file.md, ``[data]``).

A split is a folder, its layout detected from its folder names (``uavid``: ``seqNN/``; ``semantic-drone``:
``original_images/``; ``aeroscapes``: ``JPEGImages/``), or a :class:`DataSpec`: a named layout, or patterns
(an ``images`` glob and a ``labels`` template), how its label maps code classes (``rgb``: the label set's palette;
``ids``: grey class ids), a poses CSV and a list file of the frames to read. Every layout yields the same
``Sample`` objects, and a sample carries its label encoding, so a campaign worker decodes a frame's ground truth
with nothing but its sample (:func:`read_sample_labels`).
"""

from __future__ import annotations

import os
import re
import string
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from assurance.dataio import uavid
from assurance.dataio.poses import POSES_FILE, read_poses
from assurance.dataio.uavid import META_DIR, Sample, check_same_size
from el.base import userfiles
from el.base.errors import DataError
from el.base.imageio import image_size
from el.classes.labels import LabelSet

LAYOUTS = ("uavid", "semantic-drone", "aeroscapes", "pairs")
ENCODINGS = ("rgb", "ids")
PLACEHOLDERS = ("stem", "name", "dir")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
KEYS = ("path", "layout", "images", "labels", "label_encoding", "id_offset", "poses", "split")
_SEQ = re.compile(r"^seq\d+$")


@dataclass(frozen=True)
class Convention:
    """A named flat layout: the folder that identifies it, where its images and label maps lie, how they code
    classes (``id_offset``: a grey value ``v`` is class ``v - id_offset``, values below it unlabelled)."""

    marker: str
    images: str
    labels: str
    label_encoding: str
    id_offset: int = 0


CONVENTIONS = {
    # the Semantic Drone Dataset: grey maps 0 = unlabeled, 1..23 = its classes in class_dict order (the packaged
    # semantic_drone label set numbers them 0..22, unlabeled being its ignore colour)
    "semantic-drone": Convention("original_images", "original_images/*", "label_images_semantic/{stem}.png", "ids", 1),
    # AeroScapes (VOC-like): JPEGImages/*.jpg, grey SegmentationClass/*.png 0..11, lists in ImageSets/
    "aeroscapes": Convention("JPEGImages", "JPEGImages/*", "SegmentationClass/{stem}.png", "ids", 0),
    # a flat folder of pairs: NAME.jpg|png with labels/NAME.png when a labels/ folder exists, else NAME_label.png
    "pairs": Convention("", "*", "{stem}_label.png", "rgb"),
}
PAIRS_LABEL_DIR = "labels"


@dataclass(frozen=True)
class DataSpec:
    """Where a split's frames lie and how to read them: ``path`` (the root), a ``layout`` (None: detected, or the
    ``images``/``labels`` patterns), ``label_encoding`` and ``id_offset`` (None: the layout's), ``poses`` (a CSV
    ``frame,height_m,pitch_deg[,roll_deg]`` keyed by image stem) and ``split`` (a list file of the frames to read).
    Patterns, poses and split are relative to ``path`` and must stay under it. Path-like: ``os.fspath`` is the
    root, so code that only needs the folder (hashing, messages) takes it unchanged."""

    path: Path
    layout: str | None = None
    images: str | None = None
    labels: str | None = None
    label_encoding: str | None = None
    id_offset: int | None = None
    poses: str | None = None
    split: str | None = None

    def __post_init__(self) -> None:
        # normalised once (``sys/../raw`` -> ``raw``), as the label paths found under it are: one path, one spelling
        object.__setattr__(self, "path", Path(os.path.normpath(self.path)))
        if self.layout is not None and self.layout not in LAYOUTS:
            raise ValueError(f"layout: {self.layout!r} is not a known layout ({', '.join(LAYOUTS)})")
        if self.label_encoding is not None and self.label_encoding not in ENCODINGS:
            raise ValueError(f"label_encoding: must be one of {', '.join(ENCODINGS)}, got {self.label_encoding!r}")
        if self.id_offset is not None and (isinstance(self.id_offset, bool) or not isinstance(self.id_offset, int)
                                           or not 0 <= self.id_offset <= 255):
            raise ValueError(f"id_offset: must be an integer in 0..255, got {self.id_offset!r}")
        if self.labels is not None and self.images is None:
            raise ValueError("labels: a labels template needs an images pattern")
        for key in ("images", "labels", "poses", "split"):
            _check_relative(key, getattr(self, key))
        if self.labels is not None:
            _check_template(self.labels)

    def __fspath__(self) -> str:
        return str(self.path)

    def __str__(self) -> str:
        return str(self.path)

    def to_dict(self) -> dict[str, Any]:
        """The spec as data (a run's manifest records it): the keys set, the root as given."""
        out: dict[str, Any] = {"path": str(self.path)}
        out.update({f.name: getattr(self, f.name) for f in fields(self)[1:] if getattr(self, f.name) is not None})
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DataSpec:
        """A spec from a ``[data]`` table (``path`` already resolved); ValueError naming the key and the problem."""
        unknown = sorted(set(d) - set(KEYS))
        if unknown:
            raise ValueError(f"{unknown[0]}: not a key of a data table ({', '.join(KEYS)})")
        if not d.get("path"):
            raise ValueError("path: missing (the folder of the split)")
        if d.get("layout") is not None and (d.get("images") is not None or d.get("labels") is not None):
            raise ValueError("layout: give a layout or images/labels patterns, not both")
        return cls(**{k: d[k] for k in KEYS if d.get(k) is not None})


DataSource = str | Path | DataSpec


def _check_relative(key: str, value: str | None) -> None:
    """Refuse a pattern or file that would leave the data root (absolute, or with a ``..`` part; a labels template
    may climb out of ``{dir}``: each label path it names is checked to stay under the root when it is read)."""
    if value is None:
        return
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{key}: must be a non-empty string, got {value!r}")
    if Path(value).is_absolute() or (key != "labels" and ".." in Path(value).parts):
        raise ValueError(f"{key}: {value!r} must be relative to path and stay under it")


def _check_template(template: str) -> None:
    """A labels template names each image's label through {stem}, {name} or {dir}, and at least {stem} or {name}."""
    try:
        names = {f for _, f, _, _ in string.Formatter().parse(template) if f is not None}
    except ValueError as exc:
        raise ValueError(f"labels: {template!r} is not a template ({exc})") from None
    bad = sorted(names - set(PLACEHOLDERS))
    if bad:
        raise ValueError(f"labels: unknown placeholder {{{bad[0]}}} in {template!r} (known: "
                         + ", ".join(f"{{{p}}}" for p in PLACEHOLDERS) + ")")
    if not names & {"stem", "name"}:
        raise ValueError(f"labels: {template!r} names the same file for every image (use {{stem}} or {{name}})")


def as_spec(source: DataSource) -> DataSpec:
    """``source`` as a spec: a spec unchanged, a folder as a spec whose layout is detected when read."""
    return source if isinstance(source, DataSpec) else DataSpec(Path(source))


def located(source: DataSource) -> dict[str, Any]:
    """Where ``source`` is and how it is read, as a record: its spec with the absolute root (what a fitted file
    keeps of its data, so the evidence report finds the frames again from any working directory)."""
    spec = as_spec(source)
    return {**spec.to_dict(), "path": spec.path.resolve().as_posix()}


def data_source(record: Mapping[str, Any]) -> Path | DataSpec:
    """What a run read, from its manifest's ``data`` record: its spec when it recorded one, else its folder (also
    for a spec that does not read: the data's hash then tells whether the frames are the run's)."""
    spec = record.get("spec")
    try:
        return DataSpec.from_dict(spec) if isinstance(spec, Mapping) else Path(str(record["path"]))
    except (TypeError, ValueError):
        return Path(str(record["path"]))


def detect_layout(root: Path) -> str:
    """The layout of a folder from its folder names; DataError naming the folder and the known layouts."""
    if not root.is_dir():
        raise DataError(f"{root}: dataset folder not found")
    if any(p.is_dir() and _SEQ.match(p.name) for p in root.iterdir()):
        return "uavid"
    for name in ("semantic-drone", "aeroscapes"):
        if (root / CONVENTIONS[name].marker).is_dir():
            return name
    raise DataError(f"{root}: no known data layout (no seqNN/ folders: uavid, no original_images/: semantic-drone, "
                    f"no JPEGImages/: aeroscapes); layouts known: {', '.join(LAYOUTS)}, or give images and labels "
                    "patterns in a [data] table")


def resolve(source: DataSource) -> DataSpec:
    """The spec with its layout detected and its patterns, encoding and offset filled in from the layout's
    convention (``uavid`` keeps no patterns: ``assurance.dataio.uavid`` reads it)."""
    spec = as_spec(source)
    if spec.images is not None:
        return replace(spec, label_encoding=spec.label_encoding or "rgb", id_offset=spec.id_offset or 0)
    layout = spec.layout or detect_layout(spec.path)
    if layout == "uavid":
        return replace(spec, layout=layout, label_encoding=spec.label_encoding or "rgb", id_offset=spec.id_offset or 0)
    conv = CONVENTIONS[layout]
    labels = conv.labels
    if layout == "pairs" and (spec.path / PAIRS_LABEL_DIR).is_dir():
        labels = f"{PAIRS_LABEL_DIR}/{{stem}}.png"
    return replace(spec, layout=layout, images=conv.images, labels=labels,
                   label_encoding=spec.label_encoding or conv.label_encoding,
                   id_offset=conv.id_offset if spec.id_offset is None else spec.id_offset)


def iter_samples(source: DataSource, *, require_labels: bool = True, check_sizes: bool = False,
                 poses: bool = False) -> Iterator[Sample]:
    """The samples of a split in any layout, sorted by (sequence, frame); ``uavid.iter_samples``'s options.

    DataError naming the file for a missing root, an unknown layout, no image, an image without its label map
    (with ``require_labels``), two images of one frame, a list file naming no image, and (with ``poses``) a poses
    CSV that is malformed, names a frame without an image or names a stem several images share."""
    spec = resolve(source)
    if spec.layout == "uavid":
        found = list(uavid.iter_samples(spec.path, require_labels=require_labels,
                                        poses=poses and spec.poses is None))
        found = [replace(s, label_encoding=spec.label_encoding or "rgb", id_offset=spec.id_offset or 0)
                 for s in found]
    else:
        found = _pattern_samples(spec, require_labels)
    if poses:
        found = _with_poses(spec, found)
    if spec.split is not None:
        found = _in_split(spec, found)
    if check_sizes:
        for s in found:
            if s.label_path is not None:
                check_same_size(s.image_path, s.label_path)
    return iter(found)


_LITERAL_SUFFIX = re.compile(r"^(.*)\.([A-Za-z0-9]+)$")


def _glob_any_case_suffix(root: Path, pattern: str) -> list[Path]:
    """``root.glob(pattern)``, the literal extension of its last part matched in any case (``*.jpg`` finds
    ``IMG_1.JPG`` too: cameras write both), as the layouts' suffix checks are."""
    head, _, last = pattern.rpartition("/")
    m = _LITERAL_SUFFIX.match(last)
    if m is None or any(ch in m.group(2) for ch in "*?[]"):
        return list(root.glob(pattern))
    wide = f"{head}/{m.group(1)}.*" if head else f"{m.group(1)}.*"
    ext = m.group(2).lower()
    return [p for p in root.glob(wide) if p.suffix[1:].lower() == ext]


def _pattern_samples(spec: DataSpec, require_labels: bool) -> list[Sample]:
    """The samples a spec's patterns find: images matching ``images`` that are no image's label map, each paired
    with the file ``labels`` names for it; sequence = the image's folder under the root (the layout's name, or
    ``data``, for images at the root), frame = its stem."""
    root = spec.path
    if not root.is_dir():
        raise DataError(f"{root}: dataset folder not found")
    assert spec.images is not None
    found = sorted(p for p in _glob_any_case_suffix(root, spec.images)
                   if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    label_of = {p: _label_path(root, p, spec.labels) for p in found} if spec.labels is not None else {}
    taken = set(label_of.values())
    images = [p for p in found if p not in taken]
    if not images:
        raise DataError(f"{root}: no image matches {spec.images!r} ({', '.join(IMAGE_SUFFIXES)} files)")
    if require_labels and spec.labels is None:
        raise DataError(f"{root}: no labels pattern: the label maps of its images are needed here")
    samples: dict[str, Sample] = {}
    for img in images:
        rel = img.parent.relative_to(root)
        label = label_of.get(img)
        if label is not None and not label.is_file():
            if require_labels:
                raise DataError(f"{img}: image has no label map ({label} not found)")
            label = None
        sample = Sample(rel.as_posix() if rel.parts else (spec.layout or "data"), img.stem, img, label,
                        label_encoding=spec.label_encoding or "rgb", id_offset=spec.id_offset or 0,
                        meta_dir=root / META_DIR / rel)
        if sample.key in samples:
            raise DataError(f"{img}: a second image of frame {sample.key!r} (the first: "
                            f"{samples[sample.key].image_path.name})")
        samples[sample.key] = sample
    return sorted(samples.values(), key=lambda s: (s.sequence, s.frame))


def _label_path(root: Path, image: Path, template: str) -> Path:
    """The label map ``template`` names for ``image``, normalised; DataError when it would lie outside ``root``."""
    folder = image.parent.relative_to(root).as_posix()
    path = Path(os.path.normpath(root / template.format(stem=image.stem, name=image.name, dir=folder)))
    try:
        path.relative_to(os.path.normpath(root))
    except ValueError:
        raise DataError(f"{image}: its label map {path} lies outside {root}") from None
    return path


def _with_poses(spec: DataSpec, samples: list[Sample]) -> list[Sample]:
    """The samples with their poses from the spec's CSV (``poses``; for a flat layout ``ROOT/poses.csv`` when
    there is one), keyed by image stem. A UAVid split without ``poses`` keeps its per-sequence sidecars."""
    if spec.poses is None and spec.layout == "uavid":
        return samples
    path = spec.path / (spec.poses or POSES_FILE)
    if spec.poses is None and not path.exists() and not path.is_symlink():
        return samples
    table = read_poses(path)  # a missing declared file, a FIFO, a bad line: DataError naming it
    by_stem: dict[str, list[Sample]] = {}
    for s in samples:
        by_stem.setdefault(s.frame, []).append(s)
    unknown = sorted(set(table) - set(by_stem))
    if unknown:
        raise DataError(f"{path}: frame {unknown[0]!r} has no image under {spec.path}"
                        + (f" ({len(unknown)} unknown frames)" if len(unknown) > 1 else ""))
    shared = sorted(f for f in table if len(by_stem[f]) > 1)
    if shared:
        keys = ", ".join(s.key for s in by_stem[shared[0]][:3])
        raise DataError(f"{path}: frame {shared[0]!r} names {len(by_stem[shared[0]])} images ({keys}): "
                        "a poses file keys frames by stem, give each sequence its own")
    out = []
    for s in samples:
        fp = table.get(s.frame)
        out.append(replace(s, pose=fp.pose if fp else None, roll_deg=fp.roll_deg if fp else 0.0, poses_path=path))
    return out


def _in_split(spec: DataSpec, samples: list[Sample]) -> list[Sample]:
    """The samples a list file names (one frame a line: stem, key or path under the root, with or without its
    suffix; ``#`` comments), in sorted order; DataError naming the file and line of an entry with no image."""
    assert spec.split is not None
    path = spec.path / spec.split
    try:
        text = userfiles.read_text(path, what="split list", max_bytes=userfiles.MAX_POSES_BYTES,
                                   encoding="utf-8-sig")
    except userfiles.UserFileError as exc:
        raise DataError(str(exc)) from None
    names: dict[str, set[str]] = {}
    for s in samples:
        rel = s.image_path.relative_to(spec.path).with_suffix("").as_posix()
        for name in {s.frame, s.key, rel}:
            names.setdefault(name, set()).add(s.key)
    chosen: set[str] = set()
    for line, raw in enumerate(text.splitlines(), start=1):
        entry = raw.split("#", 1)[0].strip()
        if not entry:
            continue
        stem = entry[: -len(Path(entry).suffix)] if Path(entry).suffix.lower() in IMAGE_SUFFIXES else entry
        if stem not in names:
            raise DataError(f"{path}:{line}: {entry!r} names no image under {spec.path}")
        chosen |= names[stem]
    return [s for s in samples if s.key in chosen]


def read_sample_labels(sample: Sample, labels: LabelSet) -> np.ndarray:
    """A sample's ground truth as class ids (H, W) uint8, decoded as its label encoding says; DataError naming the
    file when it has none, or for a colour or value that is not a class of ``labels``."""
    if sample.label_path is None:
        raise DataError(f"{sample.image_path}: no label map")
    return read_label_file(sample.label_path, labels, encoding=sample.label_encoding, id_offset=sample.id_offset)


def read_label_file(path: str | Path, labels: LabelSet, *, encoding: str = "rgb", id_offset: int = 0) -> np.ndarray:
    """A label map as class ids (H, W) uint8: ``rgb``, colours of ``labels``' palette; ``ids``, an 8-bit grey (or
    palette-index) map whose value ``v`` is class ``v - id_offset``, a value below ``id_offset`` or equal to the set's
    ignore id reading as the ignore id. DataError naming the file and the first bad value (and where it is)."""
    if encoding == "rgb":
        try:
            return uavid.read_labels(path, labels)
        except DataError as exc:
            if "single-channel" not in str(exc):
                raise
            raise DataError(f"{exc} (a grey label map: set label_encoding = \"ids\" if its values are class "
                            "ids)") from None
    if encoding != "ids":
        raise ValueError(f"label_encoding: must be one of {', '.join(ENCODINGS)}, got {encoding!r}")
    return ids_from_values(_grey_values(Path(path)), labels, id_offset=id_offset, source=path)


def _grey_values(path: Path) -> np.ndarray:
    """The pixel values (H, W) uint8 of an 8-bit grey or palette label map (palette indices, not colours); an RGB
    file whose three channels agree is read as grey. Size refused above the pixel limit before decoding."""
    from PIL import Image, UnidentifiedImageError

    image_size(path)  # DataError: missing, or above the pixel limit (from the header)
    try:
        with Image.open(path) as img:
            mode = img.mode
            values = np.asarray(img)
    except (OSError, UnidentifiedImageError, Image.DecompressionBombError) as exc:
        raise DataError(f"{path}: not a readable label map ({exc})") from None
    if mode in ("L", "P") and values.dtype == np.uint8 and values.ndim == 2:
        return values
    if mode in ("RGB", "RGBA") and values.ndim == 3 and (values[..., 0] == values[..., 1]).all() \
            and (values[..., 0] == values[..., 2]).all():
        return np.ascontiguousarray(values[..., 0])
    hint = " with colours (set label_encoding = \"rgb\" for a colour map)" if mode.startswith("RGB") else ""
    raise DataError(f"{path}: an id label map must be 8-bit grey (or palette indices), got mode {mode}{hint}")


def ids_from_values(values: np.ndarray, labels: LabelSet, *, id_offset: int = 0,
                    source: str | Path = "<array>") -> np.ndarray:
    """Class ids (H, W) uint8 of grey values: ``v - id_offset``; below ``id_offset``, or the set's ignore id, the
    ignore id. DataError naming ``source``, the value and a pixel where it is when a value is no class."""
    v = np.asarray(values).astype(np.int32)
    n, ignore = len(labels.names), labels.ignore_id
    ids = v - id_offset
    unlabelled = ids < 0
    if ignore is not None:
        unlabelled |= v == ignore
    bad = ~unlabelled & (ids >= n)
    if ignore is None:
        bad |= unlabelled
    if bad.any():
        y, x = (int(i[0]) for i in np.nonzero(bad))
        known = f"values {id_offset}..{id_offset + n - 1} are its {n} classes" + (
            "" if ignore is None else f", {ignore}" + (f" and 0..{id_offset - 1}" if id_offset else "") + " unlabelled")
        raise DataError(f"{source}: value {int(v[y, x])} at (x={x}, y={y}) is not a class of label set "
                        f"{labels.name!r} ({known})")
    return np.where(unlabelled, ignore if ignore is not None else 0, ids).astype(np.uint8)


def write_label_file(path: str | Path, ids: np.ndarray, labels: LabelSet, *, encoding: str = "rgb",
                     id_offset: int = 0) -> None:
    """Write class ids (H, W) as a label map in ``encoding`` (the inverse of :func:`read_label_file`: an ignored
    pixel is written as value 0 below a positive ``id_offset``, else as the ignore id)."""
    if encoding == "rgb":
        uavid.write_labels(path, ids, labels)
        return
    ids = np.asarray(ids)
    labels.ids_to_colors(ids)  # ValueError for an id that is no class nor the ignore id
    ignore = labels.ignore_id
    ignored = np.zeros(ids.shape, bool) if ignore is None else ids == ignore
    values = np.where(ignored, 0 if id_offset else ignore or 0, ids.astype(np.int32) + id_offset)
    if values.max(initial=0) > 255:
        raise ValueError(f"{path}: class ids plus id_offset {id_offset} exceed 255")
    import cv2

    ok, buf = cv2.imencode(".png", values.astype(np.uint8))
    if not ok:
        raise DataError(f"{path}: could not encode the label map")
    uavid.atomic_write_bytes(Path(path), buf.tobytes())
