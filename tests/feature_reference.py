"""The learned monitor's features as they were computed before ``el.monitors.learned`` computed them in one pass per
patch and one window per frame: one plain helper per feature group, kept here only as the reference the faster code
is checked against bit for bit (tests/test_feature_identity.py, tests/test_learned_monitor.py)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from el.base.decision import Disc
from el.classes.labels import LabelSet
from el.geometry.discs import disc_window_mask
from el.landing.forbidden import forbidden_pixels, top_scores
from el.monitors.learned import CONTEXT_SCALES, frame_window
from el.monitors.lhd import take_disc
from el.monitors.patches import Patch


def disc_stats(pixel_scores: np.ndarray, labels: LabelSet) -> list[float]:
    """The four disc statistics (el.monitors.learned._DISC_STATS) of the softmax of the disc's pixels (C, m)."""
    if pixel_scores.shape[1] == 0:
        return [1.0, 1.0, 1.0, 1.0]  # nothing seen: as bad as it gets
    p = pixel_scores.astype(np.float64)
    forbidden_p = p[np.array(labels.forbidden_ids)].sum(axis=0)
    top_forbidden, top_safe = top_scores(p, labels)  # forbidden_pixels and argmax_slack, from one pass
    return [float(forbidden_p.max()), float(forbidden_p.mean()),
            float(np.count_nonzero(top_forbidden >= top_safe) / p.shape[1]), float((top_forbidden - top_safe).max())]


def class_max(pixel_scores: np.ndarray, labels: LabelSet) -> list[float]:
    """The largest probability of each forbidden class over the disc's pixels (C, m)."""
    if pixel_scores.shape[1] == 0:
        return [1.0] * len(labels.forbidden_ids)
    return [float(v) for v in pixel_scores[np.array(labels.forbidden_ids)].max(axis=1)]


def context_stats(frame: np.ndarray, candidate: Any, scale: float, labels: LabelSet) -> list[float]:
    """Largest and mean forbidden probability of the frame's softmax in discs of :data:`CONTEXT_SCALES`
    radii centred on the candidate (its safe disc and what lies just beyond it)."""
    h, w = frame.shape[1:]
    x0, y0, x1, y1 = frame_window((h, w), candidate, scale, max(CONTEXT_SCALES))  # around the largest disc
    window = np.ascontiguousarray(frame[np.array(labels.forbidden_ids), y0:y1, x0:x1])  # copied once, for every disc
    out: list[float] = []
    for k in CONTEXT_SCALES:
        mask = frame_disc_mask((h, w), candidate, scale, radii=k, window=(x0, y0, x1, y1))
        forbidden_p = take_disc(window, mask).astype(np.float64).sum(axis=0)
        out += [float(forbidden_p.max()), float(forbidden_p.mean())]
    return out


def frame_disc(frame: np.ndarray, candidate: Any, scale: float) -> np.ndarray:
    """The frame softmax (C, h, w) on the candidate's disc, (C, m): ``take_disc(frame, frame_disc_mask(...))``,
    the same pixels in the same order, read from a window around the disc rather than the whole frame."""
    window = frame_window(frame.shape[1:], candidate, scale, 1.0)
    x0, y0, x1, y1 = window
    return take_disc(frame[:, y0:y1, x0:x1], frame_disc_mask(frame.shape[1:], candidate, scale, window=window))


def frame_disc_mask(shape: tuple[int, int], candidate: Any, scale: float, *, radii: float = 1.0,
                    window: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Pixels of a working-resolution grid (h, w) whose centres lie in the candidate's disc.

    ``scale``: working pixels per full-resolution pixel; ``radii``: the disc's radius in radii of the
    candidate's; ``window`` ``(x0, y0, x1, y1)``: only that part of the grid (it must hold the pixel
    under the centre), so the mask is (y1 - y0, x1 - x0). At least the pixel under the centre is kept
    (a disc smaller than one working pixel).
    """
    h, w = shape
    x0, y0, x1, y1 = window or (0, 0, w, h)
    cx, cy, r = candidate.x * scale, candidate.y * scale, candidate.radius_px * scale * radii
    mask = disc_window_mask(Disc(cx, cy, r), x0, y0, x1, y1)  # the one disc rasterisation, on the working grid
    if not mask.any():
        mask[min(max(int(cy), 0), h - 1) - y0, min(max(int(cx), 0), w - 1) - x0] = True
    return mask


def edge_distance(patch_probs: np.ndarray, patch: Patch, candidate: Any, margin: float,
                  labels: LabelSet) -> float:
    """Distance from the disc's edge to the nearest predicted-forbidden pixel of the HD patch, in radii.

    < 0 when one lies inside the disc (-1 at the centre); the patch's reach ``(1 + margin) sqrt(2) - 1``
    when the patch holds none. Patch pixel centres are mapped back to full-resolution coordinates.
    """
    cap = (1.0 + margin) * math.sqrt(2.0) - 1.0
    ys, xs = np.nonzero(forbidden_pixels(patch_probs, labels))
    if ys.size == 0:
        return cap
    x = patch.offset[0] + (xs + 0.5) / patch.scale - candidate.x
    y = patch.offset[1] + (ys + 0.5) / patch.scale - candidate.y
    d = float(np.sqrt((x * x + y * y).min())) / candidate.radius_px - 1.0
    return min(max(d, -1.0), cap)


