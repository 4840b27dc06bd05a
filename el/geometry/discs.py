"""Which pixels a landing disc covers: the one definition the monitors and the ground truth share.

A full-resolution pixel (row r, column c) covers [c, c+1) x [r, r+1); it belongs to a disc when its
centre ``(c + 0.5, r + 0.5)`` lies within ``radius_px`` of the disc's centre (boundary included).
The LHD monitor judges exactly these pixels of its HD patch (``el.monitors.patches``) and the true
hazard of a readout counts exactly these pixels of the ground truth (``assurance.campaign.truth``): if the
two differed, a monitor could be scored on pixels it never saw (docs/architecture.md section 3.6).
"""

from __future__ import annotations

import math

import numpy as np

from el.base.decision import Disc


def disc_bounds(disc: Disc, width: int, height: int) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)``: a window of the ``width`` x ``height`` image holding every pixel of the
    disc (columns x0..x1-1, rows y0..y1-1, clipped to the image; empty when x1 <= x0 or y1 <= y0)."""
    r = disc.radius_px
    x0, x1 = max(0, math.floor(disc.x - r)), min(width, math.ceil(disc.x + r) + 1)
    y0, y1 = max(0, math.floor(disc.y - r)), min(height, math.ceil(disc.y + r) + 1)
    return x0, y0, x1, y1


def disc_window_mask(disc: Disc, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """ndarray of shape (y1 - y0, x1 - x0), bool: the pixels of the window that lie in the disc.

    The window is given in full-resolution pixel indices (columns x0..x1-1, rows y0..y1-1) and may
    be larger than the disc (a monitor's patch has a context margin).
    """
    return window_sq_distances(disc.x, disc.y, x0, y0, x1, y1) <= disc.radius_px * disc.radius_px


def window_sq_distances(x: float, y: float, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """ndarray of shape (y1 - y0, x1 - x0), float64: the squared distance from each pixel centre of the window to
    the point (x, y), as :func:`disc_window_mask` compares it (one grid serves every disc with that centre)."""
    cols = np.arange(x0, x1, dtype=np.float64) + 0.5 - x
    rows = np.arange(y0, y1, dtype=np.float64) + 0.5 - y
    return rows[:, None] ** 2 + cols[None, :] ** 2
