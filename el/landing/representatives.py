"""Representatives of the regions: proportional K-means per region, snapped into the region.

Region k of N_k valid pixels gets ``max(1, round(N* N_k / N))`` centres from the project's seeded
NumPy Lloyd K-means with k-means++ seeding, each snapped to the nearest pixel of its region
(docs/architecture.md section 3.4).
"""

from __future__ import annotations

import math

import numpy as np

from el.base.deadline import checkpoint
from el.landing.regions import Regions


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
        checkpoint("representatives")
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
