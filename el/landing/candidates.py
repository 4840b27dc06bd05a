"""Landing candidates from a segmentation at working resolution (docs/architecture.md sections 3.3-3.4).

Pipeline (all at working resolution, pixel indices (row, col); pixel (i, j) covers the square
[j, j+1) x [i, i+1) and its centre is (j + 0.5, i + 0.5)):

1. ``forbidden_from_probs``: building, road, static car, moving car win the argmax.
2. ``valid_pixels``: a pixel is valid when its disc of radius R_px(row) holds no forbidden pixel,
   lies wholly inside the image and its row is reachable.
3. ``el.landing.regions.regions_fast`` (default) / ``regions_dbscan`` (reference): group valid pixels as
   DBSCAN does.
4. ``el.landing.representatives.representatives``: N_k* = max(1, round(N* N_k / N)) K-means centroids per
   region, each snapped to the nearest pixel of its region.
5. ``prune_overlaps``: after ranking (``el.landing.ranking``), drop a candidate whose disc overlaps an
   already kept one by more than ``overlap_max`` of its area.

Conservative pooling (``pool_label_counts``, ``pool_forbidden``) brings full-resolution label
maps or forbidden masks down to working resolution: a working pixel is forbidden if **any**
source pixel overlapping it is forbidden, so thin roads and small cars survive.

Which classes are forbidden is the label set's word (``labels``, default :data:`el.classes.labels.UAVID`).

Why a margin of sqrt(2)/2 px in the clearance: the requirement holds at full resolution. Every
full-resolution forbidden pixel lies inside the square of a forbidden working pixel (conservative
pooling), and the distance from a centre to any point of a pixel's square is at least the distance
between pixel centres minus sqrt(2)/2. So ``clearance = EDT - sqrt(2)/2 > R`` keeps every point of
every forbidden full-resolution pixel out of the disc, whatever the scale between the two grids.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from el.classes.labels import LabelSet
from el.geometry.camera import NUM_STRIPES, CameraGeometry, SafetyParams
from el.landing.forbidden import forbidden_pixels

# Distance from a pixel centre to the farthest point of its square, plus a float32 guard.
CELL_MARGIN = math.sqrt(2.0) / 2.0 + 1e-4
# The same for the Chebyshev (square) distance of paper mode.
SQUARE_MARGIN = 0.5 + 1e-4
# Distances are capped here (px): far beyond any safety radius or d_max at practical working sizes.
DIST_CAP = 1024.0


# ----------------------------------------------------------------------------------------------
# 1. Forbidden pixels and conservative pooling
# ----------------------------------------------------------------------------------------------
def forbidden_from_probs(probs: np.ndarray, *, labels: LabelSet) -> np.ndarray:
    """(H, W) bool: True where a forbidden class has the highest probability.

    A tie between a forbidden and a safe class counts as forbidden (the conservative side): the one
    rule, :func:`el.landing.forbidden.forbidden_pixels`, here for a whole frame.
    """
    n = labels.num_classes
    if probs.ndim != 3 or probs.shape[0] != n:
        raise ValueError(f"probs must have shape ({n}, H, W), got {probs.shape}")
    return forbidden_pixels(probs, labels)


def _overlap_ranges(src: int, dst: int) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``dst`` target cells along an axis of ``src`` source pixels: [start, end) of the
    source pixels that overlap it (exact integer arithmetic; neighbouring ranges may share a pixel)."""
    t = np.arange(dst, dtype=np.int64)
    start = (t * src) // dst
    end = -((-(t + 1) * src) // dst)  # ceil((t + 1) * src / dst)
    return start, end


Ranges = tuple[np.ndarray, np.ndarray]


def _box_counts(mask: np.ndarray, ry: Ranges, rx: Ranges) -> np.ndarray:
    """Number of True source pixels in each target cell's overlap box, via an integral image."""
    src = np.ascontiguousarray(mask, dtype=bool).view(np.uint8)
    integral = cv2.integral(src, sdepth=cv2.CV_32S)
    (y0, y1), (x0, x1) = ry, rx
    return (integral[np.ix_(y1, x1)] - integral[np.ix_(y0, x1)] - integral[np.ix_(y1, x0)]
            + integral[np.ix_(y0, x0)])


def pool_forbidden(forbidden: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Bring a full-resolution forbidden mask (H, W) bool to ``size = (w, h)``: any-pooling.

    A target pixel is forbidden if any source pixel overlapping its area is forbidden.
    """
    forbidden = np.ascontiguousarray(forbidden, dtype=bool)
    if forbidden.ndim != 2:
        raise ValueError(f"forbidden mask must be 2-D, got shape {forbidden.shape}")
    w, h = size
    ry, rx = _overlap_ranges(forbidden.shape[0], h), _overlap_ranges(forbidden.shape[1], w)
    return _box_counts(forbidden, ry, rx) > 0


def pool_label_counts(ids: np.ndarray, size: tuple[int, int], *, labels: LabelSet) -> np.ndarray:
    """Per class, how many source pixels of the class overlap each target pixel: (C, h, w) int32."""
    ids = np.asarray(ids)
    n = labels.num_classes
    if ids.ndim != 2:
        raise ValueError(f"label map must be 2-D class ids, got shape {ids.shape}")
    if ids.size and (ids.min() < 0 or ids.max() >= n):
        raise ValueError(f"class ids must lie in 0..{n - 1}, got {ids.min()}..{ids.max()}")
    w, h = size
    if w < 1 or h < 1:
        raise ValueError(f"target size must be positive, got {size}")
    ry, rx = _overlap_ranges(ids.shape[0], h), _overlap_ranges(ids.shape[1], w)
    present = np.bincount(ids.ravel(), minlength=n) > 0
    out = np.zeros((n, h, w), dtype=np.int32)
    for c in np.flatnonzero(present):
        out[c] = _box_counts(ids == c, ry, rx)
    return out


def pooled_label_ids(ids: np.ndarray, size: tuple[int, int], *, labels: LabelSet) -> np.ndarray:
    """Class ids at ``size = (w, h)`` with conservative pooling: (h, w) uint8.

    A target pixel that any forbidden source pixel overlaps takes the forbidden class with the
    largest overlapping count (ties: lowest id); the others take the safe class with the largest
    count (ties: lowest id).
    """
    counts = pool_label_counts(ids, size, labels=labels)
    fids = np.array(labels.forbidden_ids)
    sids = np.array(labels.safe_ids)
    fcounts = counts[fids]
    any_forbidden = fcounts.sum(axis=0) > 0
    out = sids[np.argmax(counts[sids], axis=0)]
    out = np.where(any_forbidden, fids[np.argmax(fcounts, axis=0)], out)
    return out.astype(np.uint8)


# ----------------------------------------------------------------------------------------------
# 2. Valid pixels
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ValidPixels:
    """The valid pixels and what validated them.

    valid : (h, w) bool
    clearance : (h, w) float32
        Lower bound (px) on the distance from the pixel centre to the nearest point of a forbidden
        pixel or of the image border. This is the ``d`` of the distance hazard.
    radii : (h,) float64
        The radius R_px that validates each row (per stripe in paper mode).
    min_row : int
        First row where a candidate may lie.
    """

    valid: np.ndarray
    clearance: np.ndarray
    radii: np.ndarray
    min_row: int


def row_radii(
    geometry: CameraGeometry, safety: SafetyParams | None = None, mode: str = "exact"
) -> np.ndarray:
    """Safety radius (px) per row, shape (height,).

    "exact": R_px(i) of each row. "paper": one radius per stripe, R_px at the stripe's centre row.
    """
    safety = safety or SafetyParams()
    rows = np.arange(geometry.height)
    if mode == "exact":
        return np.asarray(geometry.radius_px(rows, safety), dtype=np.float64)
    if mode != "paper":
        raise ValueError(f"mode must be 'exact' or 'paper', got {mode!r}")
    edges = geometry.stripe_edges()
    radii = np.empty(geometry.height, dtype=np.float64)
    for k in range(NUM_STRIPES):
        a, b = int(edges[k]), int(edges[k + 1])
        if b > a:
            radii[a:b] = float(geometry.radius_px(np.array([(a + b - 1) / 2.0]), safety)[0])
    return radii


def border_distance(h: int, w: int) -> np.ndarray:
    """(h, w) float32: distance from each pixel centre to the image border."""
    bi = np.minimum(np.arange(h) + 0.5, h - np.arange(h) - 0.5).astype(np.float32)
    bj = np.minimum(np.arange(w) + 0.5, w - np.arange(w) - 0.5).astype(np.float32)
    return np.minimum(bi[:, None], bj[None, :])


def valid_pixels(
    forbidden: np.ndarray, radii: np.ndarray, *, mode: str = "exact", min_row: int = 0
) -> ValidPixels:
    """Valid pixels of a forbidden mask (h, w) bool, with per-row radii (h,) in px.

    exact: valid iff ``EDT - sqrt(2)/2 > R_px(row)`` (EDT = Euclidean distance between pixel
    centres, one distance transform) and the disc lies inside the image.
    paper: valid iff no forbidden pixel within the square of half-width R_px (Chebyshev distance
    ``- 1/2 > R_px``) and the disc lies inside the image.
    Both: ``row >= min_row``.
    """
    forbidden = np.asarray(forbidden, dtype=bool)
    if forbidden.ndim != 2:
        raise ValueError(f"forbidden mask must be 2-D, got shape {forbidden.shape}")
    h, w = forbidden.shape
    radii = np.asarray(radii, dtype=np.float64)
    if radii.shape != (h,):
        raise ValueError(f"radii must have shape ({h},), got {radii.shape}")
    if not np.all(np.isfinite(radii)) or np.any(radii <= 0):
        raise ValueError("radii must be positive and finite")
    if mode not in ("exact", "paper"):
        raise ValueError(f"mode must be 'exact' or 'paper', got {mode!r}")
    border = border_distance(h, w)
    free = np.ascontiguousarray((~forbidden).view(np.uint8))
    if forbidden.any():
        clearance = _exact_edt(free) - np.float32(CELL_MARGIN)
        if mode == "paper":
            cheb = np.rint(cv2.distanceTransform(free, cv2.DIST_C, 3)) - np.float32(SQUARE_MARGIN)
            np.maximum(clearance, cheb, out=clearance)  # both are lower bounds of the true distance
    else:
        clearance = np.full((h, w), np.inf, dtype=np.float32)
        cheb = clearance
    np.minimum(clearance, border, out=clearance)
    r = radii[:, None]
    if mode == "exact":
        valid = clearance > r
    else:
        valid = (cheb > r) & (border > r)
    valid[: max(0, min(int(min_row), h))] = False
    return ValidPixels(valid=valid, clearance=clearance, radii=radii, min_row=int(min_row))


def _exact_edt(free: np.ndarray) -> np.ndarray:
    """Euclidean distance (float32) from each non-zero pixel to the nearest zero pixel, capped at
    DIST_CAP, bit-reproducible.

    OpenCV's precise transform is not bit-reproducible from call to call (1-ulp differences were
    seen on identical input), and a decision must be. The true distance is the square root of an
    integer: round the square (exact below the cap in float32) and take the root again.
    """
    edt = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    np.minimum(edt, np.float32(DIST_CAP), out=edt)
    np.multiply(edt, edt, out=edt)
    np.rint(edt, out=edt)
    return np.sqrt(edt, out=edt)


# ----------------------------------------------------------------------------------------------
# 3. Overlap pruning
# ----------------------------------------------------------------------------------------------
def circle_overlap_area(d: np.ndarray | float, r1: np.ndarray | float, r2: np.ndarray | float) -> np.ndarray:
    """Area of the intersection of two discs of radii r1, r2 whose centres are d apart."""
    d, r1, r2 = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (d, r1, r2)))
    out = np.zeros(d.shape, dtype=np.float64)
    inside = d <= np.abs(r1 - r2)
    out[inside] = math.pi * np.minimum(r1, r2)[inside] ** 2
    part = ~inside & (d < r1 + r2)
    if part.any():
        dd, a, b = d[part], r1[part], r2[part]
        c1 = np.clip((dd * dd + a * a - b * b) / (2 * dd * a), -1.0, 1.0)
        c2 = np.clip((dd * dd + b * b - a * a) / (2 * dd * b), -1.0, 1.0)
        k = (-dd + a + b) * (dd + a - b) * (dd - a + b) * (dd + a + b)
        out[part] = a * a * np.arccos(c1) + b * b * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    return out


def prune_overlaps(
    rows: np.ndarray, cols: np.ndarray, radii: np.ndarray, order: np.ndarray, overlap_max: float = 0.25
) -> np.ndarray:
    """Walk candidates in ``order`` (best first); drop one whose disc overlaps an already kept disc
    by more than ``overlap_max`` of its own area. Returns the kept indices, in order."""
    kept: list[int] = []
    ys = np.asarray(rows, dtype=np.float64)
    xs = np.asarray(cols, dtype=np.float64)
    rs = np.asarray(radii, dtype=np.float64)
    for i in np.asarray(order, dtype=np.int64):
        if kept:
            kk = np.array(kept)
            d = np.hypot(ys[kk] - ys[i], xs[kk] - xs[i])
            inter = circle_overlap_area(d, rs[i], rs[kk])
            if np.any(inter > overlap_max * math.pi * rs[i] ** 2):
                continue
        kept.append(int(i))
    return np.array(kept, dtype=np.int64)
