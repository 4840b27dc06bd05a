"""Ground truth for readouts: the true hazard of a landing disc from full-resolution labels (docs/architecture.md 4.3).

True hazard of a disc: 1 if any forbidden ground-truth pixel lies in it, else
``(1 - kappa) * H_s_true`` with ``H_s_true`` the class shares in the disc weighted by the hazard
scores (normalised by the largest score), ``kappa = 0.5``. Discs use continuous image coordinates
(pixel (r, c) has its centre at (c + 0.5, r + 0.5)), as decisions do.

Ignored ("unlabelled") pixels of a label set with an ignore colour (``LabelSet.ignore``) are unknown
ground: by default (``counts_as: forbidden``) one in the disc makes it unsafe (1), as a forbidden pixel
does; with ``counts_as: excluded`` they are left out and the shares are over the disc's labelled
pixels. A disc with no labelled pixel, or none at all, is unsafe either way.
"""

from __future__ import annotations

import numpy as np

from el.base.decision import Disc
from el.classes.labels import LabelSet
from el.geometry.discs import disc_bounds, disc_window_mask

KAPPA = 0.5


def disc_pixels(ids: np.ndarray, disc: Disc) -> np.ndarray:
    """Class ids of the full-resolution pixels whose centres lie in the disc (clipped to the image)."""
    h, w = ids.shape
    x0, y0, x1, y1 = disc_bounds(disc, w, h)
    if x1 <= x0 or y1 <= y0:
        return np.zeros(0, ids.dtype)
    return ids[y0:y1, x0:x1][disc_window_mask(disc, x0, y0, x1, y1)]


def true_hazard(ids: np.ndarray, disc: Disc, *, labels: LabelSet, kappa: float = KAPPA) -> float:
    """True hazard in [0, 1] of landing on ``disc`` given the full-resolution class ids (H, W) of ``labels``
    (default UAVid; the ignore id included when the set has one). A set whose safe classes all score 0
    gives a safe disc a hazard of 0."""
    pix = disc_pixels(ids, disc)
    if pix.size and labels.ignore is not None:
        if labels.forbidden_mask(pix).any():  # a forbidden class, or an ignored pixel counted as forbidden
            return 1.0
        pix = pix[~labels.ignored_mask(pix)]  # counts_as: excluded
    if pix.size == 0 or labels.forbidden_lut[pix].any():
        return 1.0
    if labels.max_hazard_score <= 0:
        return 0.0
    shares = np.bincount(pix, minlength=labels.num_classes) / pix.size
    return float((1.0 - kappa) * (shares @ labels.hazard_scores) / labels.max_hazard_score)
