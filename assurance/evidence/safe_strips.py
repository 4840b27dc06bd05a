"""What each safe class covers, shown rather than named: one strip of the run's own frames per safe class.

A class's name and its declared hazard category are words the applicant chose; the certification basis can pin the
category of well-known names (``el.classes.class_names``), but no word list recognises every synonym or language
(``lane``,
``tarmac``, ``Straße``, ``voiture``) or a class called ``meadow`` painted over asphalt. The report's first page
therefore shows the auditor, for each safe class, a few frames of the run's own test data with that class's pixels
tinted and every other pixel greyed: asphalt, cars or roofs under a "safe" tint are seen at a glance.

The frames are chosen deterministically: up to :data:`SAMPLE_FRAMES` frames of the run evenly spaced in key order
are read once (image and label map, decoded as the campaign decodes them, in the system's label set); for each safe
class, the :data:`FRAMES_PER_CLASS` of them in which it covers the most pixels (ties by key) are drawn. The strips
are pictures of the data, never an input to the gate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from assurance.dataio.layouts import read_sample_labels
from assurance.dataio.uavid import read_image
from assurance.evidence.gallery import jpeg_uri
from assurance.requirements.basis import class_category

SAMPLE_FRAMES = 8
"""How many of the run's frames are read to find each safe class (evenly spaced over the sorted keys)."""
FRAMES_PER_CLASS = 3
"""How many frames a class's strip shows: those where it covers the most pixels."""
TINT = (255, 0, 255)
"""The tint of the class's pixels (magenta: the colour of no class of the packaged label sets)."""
THUMB_WIDTH = 240


@dataclass(frozen=True)
class _Frame:
    key: str
    image: np.ndarray  # (h, w, 3) uint8, already reduced to the thumbnail's size
    ids: np.ndarray  # (h, w) uint8 class ids at the same size (nearest neighbour)
    counts: np.ndarray  # (n_classes,) pixels of each class at full resolution
    pixels: int


def evenly_spaced(keys: Sequence[str], n: int) -> list[str]:
    """``n`` of the sorted ``keys`` spread evenly from the first to the last (all of them when there are no more)."""
    keys = sorted(keys)
    if len(keys) <= n:
        return keys
    picks = np.linspace(0, len(keys) - 1, n).round().astype(int)
    return [keys[i] for i in sorted(set(picks.tolist()))]


def tint(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``image`` (h, w, 3) uint8 with the pixels of ``mask`` (h, w) bool blended half with :data:`TINT` and every
    other pixel greyed and darkened, so what the class covers stands out whatever its colours."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    out = np.repeat((grey * 0.55)[..., None], 3, axis=2)
    tinted = 0.5 * image.astype(np.float32) + 0.5 * np.array(TINT, np.float32)
    out[mask] = tinted[mask]
    return np.clip(out.round(), 0, 255).astype(np.uint8)


def _read_frame(sample: Any, labels: Any, width: int) -> _Frame | None:
    if sample.label_path is None:
        return None
    try:
        rgb = read_image(sample.image_path)
        ids = read_sample_labels(sample, labels)
    except Exception:  # noqa: BLE001  (data folders are not signed: a frame that cannot be read is passed over)
        return None
    if ids.shape != rgb.shape[:2]:
        return None
    counts = np.bincount(ids[ids < labels.num_classes].ravel(), minlength=labels.num_classes)  # ignored: no class
    h, w = ids.shape
    size = (width, max(1, round(h * width / w)))
    small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    small_ids = cv2.resize(ids, size, interpolation=cv2.INTER_NEAREST)
    return _Frame(sample.key, small, small_ids, counts, int(h * w))


def _category(c: Any) -> str:
    """The category the basis judges a class by, as the strip's caption says it: a well-known name's pinned one (and
    what the set declared, when it differs), else the declared one, else ``unknown: none declared``."""
    judged, pinned = class_category(c)
    if pinned is not None:
        return f"{pinned}, pinned" + (f"; declared {c.category}" if c.category not in (None, pinned) else "")
    return judged if c.category is not None else f"{judged}: none declared"


def safe_class_strips(samples: dict[str, Any], keys: Sequence[str], labels: Any, *,
                      sample_frames: int = SAMPLE_FRAMES, per_class: int = FRAMES_PER_CLASS,
                      width: int = THUMB_WIDTH) -> dict[str, Any]:
    """The first page's strips: ``{"strips": [...], "frames": n, "note": str}``.

    ``samples``: the run's samples by key (``assurance.evidence.gallery.Scenes.samples``); ``keys``: the keys the run
    evaluated; ``labels``: the system's label set. One strip per safe class, in id order: ``{"name", "category",
    "hazard", "share", "frames": [{"key", "uri", "share"}]}`` (``share``: the class's share of the pixels of the
    frames read, as text); a class found in no frame read has no picture and says so."""
    chosen = evenly_spaced([k for k in keys if k in samples], sample_frames)
    frames = [f for k in chosen if (f := _read_frame(samples[k], labels, width)) is not None]
    total = sum(f.pixels for f in frames)
    strips = []
    for c in labels.classes:
        if c.forbidden:
            continue
        ranked = sorted((f for f in frames if f.counts[c.id] > 0), key=lambda f: (-int(f.counts[c.id]), f.key))
        share = sum(int(f.counts[c.id]) for f in frames) / total if total else 0.0
        strips.append({
            "name": c.name, "category": _category(c), "hazard": f"{float(c.hazard_score):g}",
            "share": f"{share:.1%}",
            "frames": [{"key": f.key, "share": f"{int(f.counts[c.id]) / f.pixels:.1%}",
                        "uri": jpeg_uri(tint(f.image, f.ids == c.id), width)} for f in ranked[:per_class]],
        })
    note = (f"{len(frames)} frame(s) of the run's test data read (evenly spaced of {len(keys)})" if frames
            else "no frame of the run's test data with a label map could be read here")
    return {"strips": strips, "frames": len(frames), "note": note}


__all__ = ["FRAMES_PER_CLASS", "SAMPLE_FRAMES", "TINT", "evenly_spaced", "safe_class_strips", "tint"]
