"""UAVid classes, their colours, emergency-landing categories and hazard scores (docs/architecture.md section 2.1).

The table is data: every other module asks this one which classes are forbidden and how
hazardous the safe ones are, so the policy lives in one place.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from el.errors import LabelColourError


@dataclass(frozen=True)
class UavidClass:
    """One UAVid class: train id, name, label colour, EL category and hazard score."""

    id: int
    name: str
    rgb: tuple[int, int, int]
    forbidden: bool
    hazard_score: float | None  # s_l for safe classes, None for forbidden ones


CLASSES: tuple[UavidClass, ...] = (
    UavidClass(0, "clutter", (0, 0, 0), False, 2.0),
    UavidClass(1, "building", (128, 0, 0), True, None),
    UavidClass(2, "road", (128, 64, 128), True, None),
    UavidClass(3, "static_car", (192, 0, 192), True, None),
    UavidClass(4, "tree", (0, 128, 0), False, 3.0),
    UavidClass(5, "low_vegetation", (128, 128, 0), False, 0.0),
    UavidClass(6, "human", (64, 64, 0), False, 1.0),
    UavidClass(7, "moving_car", (64, 0, 128), True, None),
)

NUM_CLASSES = len(CLASSES)
CLASS_NAMES: tuple[str, ...] = tuple(c.name for c in CLASSES)
CLASS_IDS: dict[str, int] = {c.name: c.id for c in CLASSES}
FORBIDDEN_IDS: tuple[int, ...] = tuple(c.id for c in CLASSES if c.forbidden)
SAFE_IDS: tuple[int, ...] = tuple(c.id for c in CLASSES if not c.forbidden)
PALETTE = np.array([c.rgb for c in CLASSES], dtype=np.uint8)  # (8, 3), row = class id
FORBIDDEN_LUT = np.array([c.forbidden for c in CLASSES], dtype=bool)
# Hazard score per class; forbidden classes get 0 because they never lie in a valid disc.
HAZARD_SCORES = np.array([c.hazard_score or 0.0 for c in CLASSES], dtype=np.float64)
MAX_HAZARD_SCORE = float(HAZARD_SCORES.max())


def _pack(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.uint32, copy=False)
    return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]


_KEYS = _pack(PALETTE)
_ORDER = np.argsort(_KEYS)
_SORTED_KEYS = _KEYS[_ORDER]


def colors_to_ids(rgb: np.ndarray, source: str | Path = "<array>") -> np.ndarray:
    """Map an RGB label image (H, W, 3) uint8 to class ids (H, W) uint8.

    Raises LabelColourError naming ``source``, the unknown colours and their pixel counts:
    a colour outside the table is never silently mapped to a class.
    """
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise LabelColourError(f"{source}: label image must be (H, W, 3) RGB, got shape {rgb.shape}")
    keys = _pack(rgb)
    pos = np.searchsorted(_SORTED_KEYS, keys)
    pos = np.clip(pos, 0, len(_SORTED_KEYS) - 1)
    known = _SORTED_KEYS[pos] == keys
    if not known.all():
        bad, counts = np.unique(keys[~known], return_counts=True)
        order = np.argsort(-counts)[:5]
        parts = [
            f"RGB({(int(k) >> 16) & 255},{(int(k) >> 8) & 255},{int(k) & 255}) x {int(c)} px"
            for k, c in zip(bad[order], counts[order], strict=True)
        ]
        more = f" and {len(bad) - 5} more colours" if len(bad) > 5 else ""
        raise LabelColourError(
            f"{source}: {int((~known).sum())} pixels have colours that are not UAVid classes: "
            + ", ".join(parts)
            + more
        )
    return _ORDER[pos].astype(np.uint8)


def ids_to_colors(ids: np.ndarray) -> np.ndarray:
    """Map class ids (H, W) to the RGB label image (H, W, 3) uint8."""
    ids = np.asarray(ids)
    if ids.size and (ids.min() < 0 or ids.max() >= NUM_CLASSES):
        raise ValueError(f"class ids must lie in 0..{NUM_CLASSES - 1}, got {ids.min()}..{ids.max()}")
    return PALETTE[ids]


def forbidden_mask(ids: np.ndarray) -> np.ndarray:
    """True where the class id is a forbidden class (building, road, static or moving car)."""
    return FORBIDDEN_LUT[np.asarray(ids)]


class LabelSet:  # placeholder: replaced by the label-set seam (merge takes the other side)
    def __init__(self, name: str, classes: tuple[UavidClass, ...]) -> None:
        self.name, self.classes = name, classes
        self.num_classes = len(classes)


UAVID = LabelSet("uavid", CLASSES)
