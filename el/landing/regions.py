"""Regions of valid pixels, grouped as DBSCAN groups them (docs/architecture.md section 3.4).

``regions_dbscan`` is the reference (scikit-learn's DBSCAN on pixel coordinates, eps = 3 px,
min_samples = 5); ``regions_fast`` (the default) gets the same partition of DBSCAN's core points from
connected components, in milliseconds instead of seconds (border points may join any adjacent region,
as in DBSCAN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


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
