"""Ground truth for readouts: the true hazard of a landing disc from full-resolution labels (docs/architecture.md 4.3).

True hazard of a disc: 1 if any forbidden ground-truth pixel lies in it, else
``(1 - kappa) * H_s_true`` with ``H_s_true`` the class shares in the disc weighted by the hazard
scores (normalised by the largest score), ``kappa = 0.5``. Discs use continuous image coordinates
(pixel (r, c) has its centre at (c + 0.5, r + 0.5)), as decisions do.
"""

from __future__ import annotations

import math

import numpy as np

from el.decision import Disc
from el.labels import FORBIDDEN_LUT, HAZARD_SCORES, MAX_HAZARD_SCORE, NUM_CLASSES

KAPPA = 0.5


def disc_pixels(ids: np.ndarray, disc: Disc) -> np.ndarray:
    """Class ids of the full-resolution pixels whose centres lie in the disc (clipped to the image)."""
    h, w = ids.shape
    r = disc.radius_px
    x0, x1 = max(0, math.floor(disc.x - r)), min(w, math.ceil(disc.x + r) + 1)
    y0, y1 = max(0, math.floor(disc.y - r)), min(h, math.ceil(disc.y + r) + 1)
    if x1 <= x0 or y1 <= y0:
        return np.zeros(0, ids.dtype)
    cols = np.arange(x0, x1) + 0.5 - disc.x
    rows = np.arange(y0, y1) + 0.5 - disc.y
    mask = rows[:, None] ** 2 + cols[None, :] ** 2 <= r * r
    return ids[y0:y1, x0:x1][mask]


def true_hazard(ids: np.ndarray, disc: Disc, *, kappa: float = KAPPA) -> float:
    """True hazard in [0, 1] of landing on ``disc`` given the full-resolution class ids (H, W)."""
    pix = disc_pixels(ids, disc)
    if pix.size == 0 or FORBIDDEN_LUT[pix].any():
        return 1.0
    shares = np.bincount(pix, minlength=NUM_CLASSES) / pix.size
    return float((1.0 - kappa) * (shares @ HAZARD_SCORES) / MAX_HAZARD_SCORE)


def forbidden_pixel_count(ids: np.ndarray, disc: Disc) -> int:
    """Number of forbidden ground-truth pixels in the disc (0 for a structurally safe disc)."""
    return int(FORBIDDEN_LUT[disc_pixels(ids, disc)].sum())
