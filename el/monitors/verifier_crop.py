"""The verifier's view of a candidate: the full-resolution pixels of its disc and a margin, at a fixed size.

A candidate's disc has the same radius on the ground wherever it lies in the frame (``beta * R``, 3.4 m for the
shipped safety parameters; its radius in pixels follows the row, ``el.geometry.camera``), so a square of half-side
``radius_px * (1 + margin)`` around the disc's centre, resampled to ``size`` x ``size`` pixels, is a fixed ground
size in metres at a fixed resolution: the disc is always the same circle of the crop
(:func:`crop_disc_mask`). Pixels outside the frame are black (the image border counts as forbidden). Training
(``assurance.fitting.verifier_data``) and flight crop through this one function, so they cannot drift.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from el.base.decision import Candidate, Disc
from el.monitors.patches import _as_disc, validate_rgb

MAX_MARGIN = 4.0  # radii of context around the disc: beyond it a crop is mostly not the candidate, and its window
# (and the work to cut it) grows as (1 + margin)^2


def crop_window(disc: Disc, margin: float) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` (end exclusive, may leave the image): the integer square holding the disc's centre
    square of half-side ``radius_px * (1 + margin)``."""
    half = disc.radius_px * (1.0 + margin)
    x0, y0 = math.floor(disc.x - half), math.floor(disc.y - half)
    side = max(1, math.ceil(2.0 * half))
    return x0, y0, x0 + side, y0 + side


def padded_window(image: np.ndarray, x0: int, y0: int, x1: int, y1: int, fill: int = 0) -> np.ndarray:
    """``image[y0:y1, x0:x1]`` with the part outside the image set to ``fill`` (a view when it lies inside)."""
    h, w = image.shape[:2]
    if x0 >= 0 and y0 >= 0 and x1 <= w and y1 <= h:
        return image[y0:y1, x0:x1]
    out = np.full((y1 - y0, x1 - x0, *image.shape[2:]), fill, dtype=image.dtype)
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    if sx1 > sx0 and sy1 > sy0:
        out[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = image[sy0:sy1, sx0:sx1]
    return out


def resample(window: np.ndarray, size: int) -> np.ndarray:
    """``window`` resampled to ``size`` x ``size`` (area interpolation down, bilinear up)."""
    side = window.shape[0]
    interp = cv2.INTER_AREA if side >= size else cv2.INTER_LINEAR
    return cv2.resize(np.ascontiguousarray(window), (size, size), interpolation=interp)


def candidate_crop(hd_image: np.ndarray, disc: Disc | Candidate, *, size: int, margin: float) -> np.ndarray:
    """The verifier's crop of one candidate: ndarray (size, size, 3) uint8.

    Parameters
    ----------
    hd_image : ndarray of shape (H, W, 3), uint8
        The full-resolution frame.
    disc : Disc or Candidate
        Centre and radius in full-resolution pixels.
    size : int
        Side of the crop in pixels (>= 8).
    margin : float
        Context around the disc, as a fraction of its radius (>= 0).
    """
    validate_rgb(hd_image, "hd_image")
    d = _as_disc(disc)
    if isinstance(size, bool) or not isinstance(size, int) or size < 8:
        raise ValueError(f"size must be an integer >= 8, got {size!r}")
    if not (isinstance(margin, int | float) and 0.0 <= margin < math.inf):
        raise ValueError(f"margin must be a finite number >= 0, got {margin!r}")
    x0, y0, x1, y1 = crop_window(d, margin)
    h, w = hd_image.shape[:2]
    if x1 <= 0 or y1 <= 0 or x0 >= w or y0 >= h:
        raise ValueError(f"disc ({d.x:.1f}, {d.y:.1f}, r={d.radius_px:.1f}) lies outside the {w}x{h} image")
    return resample(padded_window(hd_image, x0, y0, x1, y1), size)


def crop_disc_mask(size: int, margin: float) -> np.ndarray:
    """ndarray (size, size) bool: the crop's pixels whose centres lie in the disc (the same for every candidate)."""
    c = (np.arange(size) + 0.5) / size * 2.0 * (1.0 + margin) - (1.0 + margin)
    return (c[:, None] ** 2 + c[None, :] ** 2) <= 1.0
