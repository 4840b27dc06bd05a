"""Landing candidates from a segmentation at working resolution (docs/architecture.md sections 3.3-3.4).

Pipeline (all at working resolution, pixel indices (row, col); pixel (i, j) covers the square
[j, j+1) x [i, i+1) and its centre is (j + 0.5, i + 0.5)):

1. ``forbidden_from_probs``: building, road, static car, moving car win the argmax.
2. ``valid_pixels``: a pixel is valid when its disc of radius R_px(row) holds no forbidden pixel,
   lies wholly inside the image and its row is reachable.
3. ``regions_fast`` (default) / ``regions_dbscan`` (reference): group valid pixels as DBSCAN does.
4. ``representatives``: N_k* = max(1, round(N* N_k / N)) K-means centroids per region, each snapped
   to the nearest pixel of its region.
5. ``prune_overlaps``: after ranking (``el.ranking``), drop a candidate whose disc overlaps an
   already kept one by more than ``overlap_max`` of its area.

Conservative pooling (``pool_label_counts``, ``pool_forbidden``) brings full-resolution label
maps or forbidden masks down to working resolution: a working pixel is forbidden if **any**
source pixel overlapping it is forbidden, so thin roads and small cars survive.

Why a margin of sqrt(2)/2 px in the clearance: the requirement holds at full resolution. Every
full-resolution forbidden pixel lies inside the square of a forbidden working pixel (conservative
pooling), and the distance from a centre to any point of a pixel's square is at least the distance
between pixel centres minus sqrt(2)/2. So ``clearance = EDT - sqrt(2)/2 > R`` keeps every point of
every forbidden full-resolution pixel out of the disc, whatever the scale between the two grids.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from el.camera import NUM_STRIPES, CameraGeometry, SafetyParams
from el.forbidden import forbidden_pixels
from el.labels import FORBIDDEN_IDS, NUM_CLASSES, SAFE_IDS

# Distance from a pixel centre to the farthest point of its square, plus a float32 guard.
CELL_MARGIN = math.sqrt(2.0) / 2.0 + 1e-4
# The same for the Chebyshev (square) distance of paper mode.
SQUARE_MARGIN = 0.5 + 1e-4
# Distances are capped here (px): far beyond any safety radius or d_max at practical working sizes.
DIST_CAP = 1024.0


# ----------------------------------------------------------------------------------------------
# 1. Forbidden pixels and conservative pooling
# ----------------------------------------------------------------------------------------------
def forbidden_from_probs(probs: np.ndarray) -> np.ndarray:
    """(H, W) bool: True where a forbidden class has the highest probability.

    A tie between a forbidden and a safe class counts as forbidden (the conservative side): the one
    rule, :func:`el.forbidden.forbidden_pixels`, here for a whole frame.
    """
    if probs.ndim != 3 or probs.shape[0] != NUM_CLASSES:
        raise ValueError(f"probs must have shape ({NUM_CLASSES}, H, W), got {probs.shape}")
    return forbidden_pixels(probs)


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


def pool_label_counts(ids: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Per class, how many source pixels of the class overlap each target pixel: (C, h, w) int32."""
    ids = np.asarray(ids)
    if ids.ndim != 2:
        raise ValueError(f"label map must be 2-D class ids, got shape {ids.shape}")
    if ids.size and (ids.min() < 0 or ids.max() >= NUM_CLASSES):
        raise ValueError(f"class ids must lie in 0..{NUM_CLASSES - 1}, got {ids.min()}..{ids.max()}")
    w, h = size
    if w < 1 or h < 1:
        raise ValueError(f"target size must be positive, got {size}")
    ry, rx = _overlap_ranges(ids.shape[0], h), _overlap_ranges(ids.shape[1], w)
    present = np.bincount(ids.ravel(), minlength=NUM_CLASSES) > 0
    out = np.zeros((NUM_CLASSES, h, w), dtype=np.int32)
    for c in np.flatnonzero(present):
        out[c] = _box_counts(ids == c, ry, rx)
    return out


def pooled_label_ids(ids: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Class ids at ``size = (w, h)`` with conservative pooling: (h, w) uint8.

    A target pixel that any forbidden source pixel overlaps takes the forbidden class with the
    largest overlapping count (ties: lowest id); the others take the safe class with the largest
    count (ties: lowest id).
    """
    counts = pool_label_counts(ids, size)
    fids = np.array(FORBIDDEN_IDS)
    sids = np.array(SAFE_IDS)
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
# 3. Regions: DBSCAN semantics on pixel coordinates
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Regions:
    """labels: (h, w) int32, 0 outside any region (not valid, or DBSCAN noise), 1..n inside;
    core: (h, w) bool, DBSCAN core points; n_regions: number of regions."""

    labels: np.ndarray
    core: np.ndarray
    n_regions: int


@lru_cache(maxsize=16)
def eps_offsets(eps: float) -> np.ndarray:
    """(m, 2) integer offsets (dy, dx) with dy^2 + dx^2 <= eps^2, the centre included (read-only)."""
    n = int(math.floor(eps))
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    keep = (yy * yy + xx * xx) <= eps * eps
    out = np.stack([yy[keep], xx[keep]], axis=1)
    out.flags.writeable = False
    return out


@lru_cache(maxsize=16)
def _eps_kernel(eps: float) -> np.ndarray:
    n = int(math.floor(eps))
    k = np.zeros((2 * n + 1, 2 * n + 1), dtype=np.uint8)
    off = eps_offsets(eps)
    k[off[:, 0] + n, off[:, 1] + n] = 1
    k.flags.writeable = False
    return k


def core_points(valid: np.ndarray, eps: float = 3.0, min_samples: int = 5) -> np.ndarray:
    """DBSCAN core points: valid pixels with at least ``min_samples`` valid pixels (themselves
    included) within distance ``eps``. One convolution with a disc kernel."""
    kernel = _eps_kernel(eps).astype(np.float32)
    counts = cv2.filter2D(valid.astype(np.float32), -1, kernel, borderType=cv2.BORDER_CONSTANT)
    return valid & (counts >= min_samples - 0.5)


def _bbox(mask: np.ndarray, pad: int) -> tuple[slice, slice] | None:
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    h, w = mask.shape
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + pad + 1, h)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)))


def regions_fast(valid: np.ndarray, *, eps: float = 3.0, min_samples: int = 5) -> Regions:
    """DBSCAN's regions without DBSCAN: same partition of the core points, in milliseconds.

    1. core points by one convolution (``core_points``);
    2. connected components of the core mask (8-connectivity, all within eps when eps >= sqrt 2);
    3. merge components that have core points within eps of each other but are not 8-connected.
       Such a pair always has a non-core pixel in the bounding box of the two points, hence within
       eps of both: only "fringe" core points (a non-core pixel within eps) need to be compared,
       over the half-plane of eps offsets;
    4. border points (valid, not core, a core point within eps) join one adjacent region (the
       highest label within eps; DBSCAN itself assigns them by visiting order). The rest is noise.

    Regions are numbered 1..n by the raster order of their first core point, whatever the
    connected-components implementation does, so the result is reproducible.
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim != 2:
        raise ValueError(f"valid mask must be 2-D, got shape {valid.shape}")
    h, w = valid.shape
    labels_full = np.zeros((h, w), dtype=np.int32)
    core_full = np.zeros((h, w), dtype=bool)
    n = int(math.floor(eps))
    box = _bbox(valid, n + 1)
    if box is None:
        return Regions(labels_full, core_full, 0)
    v = np.ascontiguousarray(valid[box])
    core = core_points(v, eps, min_samples)
    connectivity = 8 if eps >= math.sqrt(2.0) else 4
    n_lab, lab = cv2.connectedComponents(core.view(np.uint8), connectivity=connectivity, ltype=cv2.CV_32S)
    if n_lab > 2:
        lab, n_lab = _merge_within_eps(lab, n_lab, core, eps, connectivity)
        lab = _first_appearance_order(lab, lab, n_lab)
    n_regions = n_lab - 1
    if n_regions > 0:
        border = v & ~core
        if border.any():
            dtype = np.float32 if n_lab < 2**24 else np.float64
            kernel = _eps_kernel(eps)
            near = cv2.dilate(lab.astype(dtype), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
            lab[border] = near[border].astype(np.int32)
    labels_full[box] = lab
    core_full[box] = core
    return Regions(labels_full, core_full, n_regions)


def _merge_within_eps(lab: np.ndarray, n_lab: int, core: np.ndarray, eps: float, connectivity: int):
    kernel = _eps_kernel(eps)
    fringe = core & (cv2.erode(core.view(np.uint8), kernel) == 0)
    if not fringe.any():
        return lab, n_lab
    off = eps_offsets(eps)
    half = off[(off[:, 0] > 0) | ((off[:, 0] == 0) & (off[:, 1] > 0))]
    adjacent = np.abs(half).max(axis=1) <= 1 if connectivity == 8 else np.abs(half).sum(axis=1) <= 1
    half = half[~adjacent]
    n = int(math.floor(eps))
    padded = np.pad(lab, n)
    wp = padded.shape[1]
    ys, xs = np.nonzero(fringe)
    flat = (ys + n) * wp + (xs + n)
    a = padded.ravel()[flat]
    b = padded.ravel()[flat[:, None] + (half[:, 0] * wp + half[:, 1])[None, :]]
    hit = (b > 0) & (b != a[:, None])
    if not hit.any():
        return lab, n_lab
    src = np.broadcast_to(a[:, None], b.shape)[hit]
    dst = b[hit]
    graph = coo_matrix((np.ones(src.size, dtype=np.int8), (src, dst)), shape=(n_lab, n_lab))
    n_comp, comp = connected_components(graph, directed=False)
    # Label 0 (background) has no edge and is the first node: it keeps component 0.
    return comp.astype(np.int32)[lab], n_comp


def _first_appearance_order(lab: np.ndarray, core_lab: np.ndarray, n_lab: int) -> np.ndarray:
    """Renumber ``lab`` (0 = none, labels < n_lab) as 1..n in the raster order of the first pixel
    of each label in ``core_lab``; linear time (runs of equal labels, then a small unique)."""
    flat = core_lab.ravel()
    nz = flat[flat > 0]
    if nz.size == 0:
        return lab
    starts = np.concatenate([[0], np.flatnonzero(np.diff(nz)) + 1])
    run_labels = nz[starts]
    _, first = np.unique(run_labels, return_index=True)
    order = run_labels[np.sort(first)]
    mapping = np.zeros(max(n_lab, int(lab.max()) + 1), dtype=np.int32)
    mapping[order] = np.arange(1, len(order) + 1, dtype=np.int32)
    return mapping[lab]


def regions_dbscan(valid: np.ndarray, *, eps: float = 3.0, min_samples: int = 5) -> Regions:
    """The reference: scikit-learn's DBSCAN on the (row, col) coordinates of the valid pixels."""
    from sklearn.cluster import DBSCAN

    valid = np.asarray(valid, dtype=bool)
    h, w = valid.shape
    labels = np.zeros((h, w), dtype=np.int32)
    core = np.zeros((h, w), dtype=bool)
    coords = np.argwhere(valid)
    if len(coords) == 0:
        return Regions(labels, core, 0)
    model = DBSCAN(eps=eps, min_samples=min_samples).fit(coords)
    lab = model.labels_.astype(np.int32) + 1  # noise (-1) -> 0
    labels[coords[:, 0], coords[:, 1]] = lab
    ci = model.core_sample_indices_
    core[coords[ci, 0], coords[ci, 1]] = True
    n = int(lab.max())
    labels = _first_appearance_order(labels, np.where(core, labels, 0), n + 1)
    return Regions(labels, core, n)


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two labelings of the same items define the same partition (label values aside)."""
    a = np.asarray(a).ravel()
    b = np.asarray(b).ravel()
    if a.shape != b.shape:
        return False
    if a.size == 0:
        return True
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


# ----------------------------------------------------------------------------------------------
# 4. Representatives: proportional K-means per region, snapped into the region
# ----------------------------------------------------------------------------------------------
def kmeans(points: np.ndarray, k: int, *, seed: int = 0, n_init: int = 1, max_iter: int = 100,
           tol: float = 1e-4) -> np.ndarray:
    """Lloyd's K-means with k-means++ seeding, in NumPy: (k, d) centres of ``points`` (n, d).

    Deterministic for a given seed (no threads, no BLAS), and fast on the small point sets of a
    region (scikit-learn's KMeans gives equivalent centres but its thread pool costs from
    milliseconds to hundreds of milliseconds per call on a busy 2-core machine). Stops when the
    assignment no longer changes or the centres move less than ``tol`` (relative to the data
    variance, as in scikit-learn); the best of ``n_init`` runs (lowest inertia) is kept.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or len(pts) == 0:
        raise ValueError(f"points must be a non-empty (n, d) array, got shape {pts.shape}")
    if not 1 <= k <= len(pts):
        raise ValueError(f"k must lie in [1, {len(pts)}], got {k}")
    rng = np.random.default_rng(seed)
    d = pts.shape[1]
    cols = [np.ascontiguousarray(pts[:, j]) for j in range(d)]
    abs_tol = tol * float(np.mean(np.var(pts, axis=0)))
    best, best_inertia = None, np.inf
    for _ in range(n_init):
        centres = _kmeans_pp(pts, k, rng)
        assign = None
        for _ in range(max_iter):
            new_assign = _sq_dist(cols, centres).argmin(axis=1)
            if assign is not None and np.array_equal(new_assign, assign):
                break
            assign = new_assign
            counts = np.bincount(assign, minlength=k)
            new = np.empty_like(centres)
            for j in range(d):
                new[:, j] = np.bincount(assign, weights=cols[j], minlength=k)
            empty = counts == 0
            if empty.any():
                new[empty] = centres[empty]
                counts = np.where(empty, 1, counts)
            new /= counts[:, None]
            shift = float(((new - centres) ** 2).sum())
            centres = new
            if shift <= abs_tol:
                break
        inertia = float(_sq_dist(cols, centres).min(axis=1).sum())
        if inertia < best_inertia:
            best, best_inertia = centres, inertia
    return best


def _sq_dist(cols: list[np.ndarray], centres: np.ndarray) -> np.ndarray:
    d2 = (cols[0][:, None] - centres[None, :, 0]) ** 2
    for j in range(1, len(cols)):
        d2 += (cols[j][:, None] - centres[None, :, j]) ** 2
    return d2


def _kmeans_pp(pts: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    centres = np.empty((k, pts.shape[1]), dtype=np.float64)
    centres[0] = pts[rng.integers(len(pts))]
    d2 = ((pts - centres[0]) ** 2).sum(axis=1)
    for c in range(1, k):
        total = d2.sum()
        if total > 0:
            idx = int(np.searchsorted(np.cumsum(d2), rng.random() * total, side="right"))
            idx = min(idx, len(pts) - 1)
        else:
            idx = int(rng.integers(len(pts)))
        centres[c] = pts[idx]
        d2 = np.minimum(d2, ((pts - centres[c]) ** 2).sum(axis=1))
    return centres


def snap_to_region(labels: np.ndarray, region: int, y: float, x: float) -> tuple[int, int]:
    """The pixel (row, col) of ``region`` whose centre is nearest to the point (y, x) in index
    coordinates (ties: first in raster order). Searches growing windows, not the whole region."""
    h, w = labels.shape
    ci, cj = int(round(y)), int(round(x))
    s = 1
    while True:
        i0, i1 = max(ci - s, 0), min(ci + s + 1, h)
        j0, j1 = max(cj - s, 0), min(cj + s + 1, w)
        win = labels[i0:i1, j0:j1] == region
        if win.any():
            ii, jj = np.nonzero(win)
            d2 = (ii + i0 - y) ** 2 + (jj + j0 - x) ** 2
            k = int(np.argmin(d2))
            dmin = math.sqrt(float(d2[k]))
            covers = (i0 == 0 or ci - s <= y - dmin) and (i1 == h or ci + s >= y + dmin) and \
                     (j0 == 0 or cj - s <= x - dmin) and (j1 == w or cj + s >= x + dmin)
            if covers:
                return int(ii[k] + i0), int(jj[k] + j0)
            s = int(math.ceil(dmin)) + 1
            continue
        if i0 == 0 and j0 == 0 and i1 == h and j1 == w:
            raise ValueError(f"region {region} is empty")
        s *= 2


def representatives(
    regions: Regions,
    *,
    n_star: int = 20,
    max_points: int = 500,
    seed: int = 0,
    n_init: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Representative pixels of the regions: (rows, cols, region ids), int arrays of equal length.

    Region k of N_k pixels (N in all regions) gets N_k* = max(1, round(N* N_k / N)) (half up,
    at most N_k) K-means centroids of its pixels (a regular subsample of at most ``max_points``),
    each snapped to the nearest pixel of the region: a centroid of a U-shaped region may fall
    outside it. Duplicates (two centroids snapped to the same pixel) are kept once.
    """
    labels = regions.labels
    h, w = labels.shape
    empty = np.zeros(0, dtype=np.int64)
    if regions.n_regions == 0:
        return empty, empty, empty
    idx = np.flatnonzero(labels)
    if idx.size == 0:
        return empty, empty, empty
    lab = labels.ravel()[idx]
    if regions.n_regions > 1:
        key = lab.astype(np.uint16) if regions.n_regions < 2**16 else lab
        order = np.argsort(key, kind="stable")  # raster order inside each region
        idx, lab = idx[order], lab[order]
    counts = np.bincount(lab, minlength=regions.n_regions + 1)
    total = int(counts.sum())
    starts = np.concatenate([[0], np.cumsum(counts)])
    out_r, out_c, out_k = [], [], []
    for k in np.flatnonzero(counts):
        n_k = int(counts[k])
        pix = idx[starts[k] : starts[k + 1]]
        k_star = min(n_k, max(1, int(math.floor(n_star * n_k / total + 0.5))))
        if k_star == 1:
            rr, cc = np.divmod(pix, w)
            centres = np.array([[rr.mean(), cc.mean()]])
        else:
            step = max(1, -(-n_k // max_points))
            rr, cc = np.divmod(pix[::step], w)
            pts = np.stack([rr, cc], axis=1).astype(np.float64)
            centres = kmeans(pts, min(k_star, len(pts)), seed=seed, n_init=n_init)
        seen = set()
        for y, x in centres:
            p = snap_to_region(labels, int(k), float(y), float(x))
            if p not in seen:
                seen.add(p)
                out_r.append(p[0])
                out_c.append(p[1])
                out_k.append(int(k))
    return np.array(out_r, dtype=np.int64), np.array(out_c, dtype=np.int64), np.array(out_k, dtype=np.int64)


# ----------------------------------------------------------------------------------------------
# 5. Overlap pruning
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
