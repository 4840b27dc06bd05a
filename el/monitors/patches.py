"""HD patch geometry: the square crop around a candidate's safe disc, and the disc's pixel mask.

Coordinates are continuous full-resolution image coordinates, as in ``el.landing.core`` and the decision
JSON: pixel (row r, column c) covers [c, c+1) x [r, r+1), so its centre is ``(c + 0.5, r + 0.5)``
and the image spans [0, W] x [0, H]. A pixel belongs to the disc when its centre lies within
``radius_px`` of the disc centre.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass

import cv2
import numpy as np

from el.base.decision import Candidate, Disc
from el.base.rgb import check_rgb
from el.geometry.discs import disc_window_mask


@dataclass(frozen=True, eq=False)
class Patch:
    """A crop of the HD image around a disc.

    Attributes
    ----------
    rgb : ndarray of shape (h, w, 3), uint8
        The crop, downscaled when its side exceeded ``max_side``.
    disc_mask : ndarray of shape (h, w), bool
        Patch pixels in the disc. After a downscale, a patch pixel is in the disc when any
        full-resolution pixel under it is (conservative pooling, as in docs/architecture.md section 3.3).
    scale : float
        Patch pixels per full-resolution pixel (1.0 without downscale, < 1 with).
    offset : tuple of int
        ``(x0, y0)``: full-resolution column and row of the crop's top-left pixel.
    """

    rgb: np.ndarray
    disc_mask: np.ndarray
    scale: float
    offset: tuple[int, int]

    @property
    def shape(self) -> tuple[int, int]:
        return self.disc_mask.shape  # type: ignore[return-value]


def _as_disc(disc: object) -> Disc:
    try:
        x, y, r = float(disc.x), float(disc.y), float(disc.radius_px)  # type: ignore[attr-defined]
    except AttributeError:
        raise ValueError(f"need a Disc or Candidate (x, y, radius_px), not {type(disc).__name__}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"disc centre must be finite, got ({x!r}, {y!r})")
    if not (math.isfinite(r) and r > 0):
        raise ValueError(f"disc radius_px must be a positive finite number, got {r!r}")
    return Disc(x, y, r)


def validate_rgb(image: object, what: str = "image") -> np.ndarray:
    """Check an RGB image: ndarray of shape (H, W, 3), uint8, non-empty (``el.base.rgb.check_rgb``)."""
    return check_rgb(image, what)


def validate_patch_params(margin: float, max_side: int | None) -> None:
    """Check the patch parameters: ``margin`` finite >= 0, ``max_side`` None or an integer >= 16."""
    if isinstance(margin, bool) or not isinstance(margin, int | float) or not (0 <= margin < math.inf):
        raise ValueError(f"margin must be a finite number >= 0, got {margin!r}")
    bad_side = isinstance(max_side, bool) or not isinstance(max_side, int) or max_side < 16
    if max_side is not None and bad_side:
        raise ValueError(f"max_side must be None or an integer >= 16, got {max_side!r}")


def disc_window(disc: Disc, width: int, height: int, margin: float) -> tuple[int, int, int, int]:
    """Crop window ``(x0, y0, x1, y1)`` (end exclusive) of the square around the disc, clipped.

    The square has side ``2 ceil(r (1 + margin)) + 1`` centred on the pixel that holds the disc
    centre, so it holds every pixel of the disc for any ``margin >= 0``.
    """
    half = math.ceil(disc.radius_px * (1.0 + margin))
    cx, cy = math.floor(disc.x), math.floor(disc.y)
    x0, y0 = max(cx - half, 0), max(cy - half, 0)
    x1, y1 = min(cx + half + 1, width), min(cy + half + 1, height)
    return x0, y0, x1, y1


def extract_patch(
    hd_image: np.ndarray,
    disc: Disc | Candidate,
    *,
    margin: float = 0.25,
    max_side: int | None = None,
) -> Patch:
    """Crop the HD image around a disc (with a context margin) and build the disc mask.

    Parameters
    ----------
    hd_image : ndarray of shape (H, W, 3), uint8
        Full-resolution RGB image.
    disc : Disc or Candidate
        Anything with ``x``, ``y``, ``radius_px`` in full-resolution pixels.
    margin : float, default 0.25
        Context around the disc, as a fraction of its radius (the square's half-side is
        ``radius_px * (1 + margin)``), clipped to the image.
    max_side : int or None, default None
        Downscale (area interpolation) a crop whose longer side exceeds this many pixels;
        None keeps full resolution. A cap trades the small objects the monitor exists to see
        for time.

    Returns
    -------
    Patch

    Raises
    ------
    ValueError
        Bad image, disc, margin or max_side, or a disc with no pixel inside the image.

    Examples
    --------
    >>> import numpy as np
    >>> from el.base.decision import Candidate, Disc
    >>> p = extract_patch(np.zeros((100, 200, 3), np.uint8), Disc(50.5, 40.5, 8.0), margin=0.25)
    >>> p.rgb.shape, p.offset, int(p.disc_mask.sum())
    ((21, 21, 3), (40, 30), 197)
    """
    validate_rgb(hd_image, "hd_image")
    d = _as_disc(disc)
    validate_patch_params(margin, max_side)
    height, width = hd_image.shape[:2]
    x0, y0, x1, y1 = disc_window(d, width, height, margin)
    where = f"disc ({d.x:.1f}, {d.y:.1f}, r={d.radius_px:.1f}) has no pixel inside the {width}x{height} image"
    if x1 <= x0 or y1 <= y0:
        raise ValueError(where)
    mask = disc_window_mask(d, x0, y0, x1, y1)
    if not mask.any():
        raise ValueError(where)
    rgb = hd_image[y0:y1, x0:x1]
    scale = 1.0
    side = max(y1 - y0, x1 - x0)
    if max_side is not None and side > max_side:
        scale = max_side / side
        size = (max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale)))  # cv2: (w, h)
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0
    return Patch(rgb=np.ascontiguousarray(rgb), disc_mask=mask, scale=scale, offset=(x0, y0))


def disc_box(mask: np.ndarray) -> tuple[tuple[int, int, int, int] | None, np.ndarray]:
    """The disc's bounding box ``(y0, y1, x0, x1)`` in its patch and the mask cut to it.

    MC dropout need only produce scores there (``Segmenter.mc_dropout(..., window=)``): the rules
    read the disc's pixels and nothing else. ``(None, mask)`` for an empty mask.
    """
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return None, mask
    y0, y1, x0, x1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    return (y0, y1, x0, x1), mask[y0:y1, x0:x1]


def accepts_keyword(fn: object, name: str) -> bool:
    """Whether a callable takes the keyword ``name`` (an optional speed-up of some segmenters)."""
    try:
        return name in inspect.signature(fn).parameters  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
