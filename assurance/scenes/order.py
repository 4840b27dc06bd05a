"""Painter's order for solids standing on the ground, seen from a camera above all of them.

Two solids can only cover each other in the image if some pixel ray meets both; projected on
the ground, that ray is a half-line from the point below the camera. For disjoint convex
footprints the one the half-line enters first is in front, on every common half-line; a solid
entirely above another (a crown over a car) is in front wherever they overlap. These pairwise
relations are turned into a drawing order (far first) by a topological sort; the rare cycles
(overlapping footprints at overlapping heights) are broken by distance.
"""

from __future__ import annotations

import heapq
import math

import numpy as np


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _entry_distance(polys: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Distance from the origin along direction alpha (angle from +y toward +x) to where it enters each polygon."""
    d = np.stack([np.sin(alpha), np.cos(alpha)], axis=-1)[:, None, :]  # (m, 1, 2)
    p = polys
    e = np.roll(p, -1, axis=1) - p
    denom = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (p[..., 0] * e[..., 1] - p[..., 1] * e[..., 0]) / denom
        s = (p[..., 0] * d[..., 1] - p[..., 1] * d[..., 0]) / denom
    ok = (np.abs(denom) > 1e-12) & (s >= -1e-9) & (s <= 1 + 1e-9) & (t > 0)
    t = np.where(ok, t, np.inf)
    return t.min(axis=1)


def draw_order(footprints: np.ndarray, zmin: np.ndarray, zmax: np.ndarray, boxes: np.ndarray,
               key: np.ndarray) -> list[int]:
    """Indices of the solids in drawing order (far first).

    footprints: (n, K, 2) convex ground polygons (padded by repeating a vertex); zmin, zmax: (n,)
    height ranges; boxes: (n, 4) image bounding boxes (c0, r0, c1, r1) used to skip pairs that
    cannot overlap; key: (n,) distance used for ties and cycles (larger = drawn earlier).
    """
    n = len(footprints)
    if n == 0:
        return []
    # angular extent of each footprint seen from the origin
    ang = np.arctan2(footprints[..., 0], footprints[..., 1])
    centre = np.arctan2(footprints[..., 0].mean(axis=1), footprints[..., 1].mean(axis=1))
    rel = _wrap(ang - centre[:, None])
    lo, hi = rel.min(axis=1), rel.max(axis=1)
    # origin inside a footprint: everything is behind it
    contains = _contains_origin(footprints)
    ii, jj = _overlapping_pairs(boxes)
    if len(ii) == 0:
        return list(np.argsort(-key, kind="stable"))
    above_i = zmin[ii] >= zmax[jj] - 1e-3
    above_j = zmin[jj] >= zmax[ii] - 1e-3
    # angular overlap, measured around i's centre
    delta = _wrap(centre[jj] - centre[ii])
    o_lo = np.maximum(lo[ii], delta + lo[jj])
    o_hi = np.minimum(hi[ii], delta + hi[jj])
    overlap = (o_hi > o_lo) | contains[ii] | contains[jj]
    alpha = centre[ii] + (o_lo + o_hi) / 2
    t_i = _entry_distance(footprints[ii], alpha)
    t_j = _entry_distance(footprints[jj], alpha)
    t_i = np.where(contains[ii], 0.0, t_i)
    t_j = np.where(contains[jj], 0.0, t_j)
    i_front = np.where(above_i, True, np.where(above_j, False, t_i < t_j))
    related = above_i | above_j | (overlap & np.isfinite(np.minimum(t_i, t_j)) & (t_i != t_j))
    ii, jj, i_front = ii[related], jj[related], i_front[related]
    # edge src -> dst: src drawn before dst (dst is in front)
    src = np.where(i_front, jj, ii)
    dst = np.where(i_front, ii, jj)
    return _toposort(n, src, dst, key)


def _contains_origin(polys: np.ndarray) -> np.ndarray:
    e = np.roll(polys, -1, axis=1) - polys
    cross = e[..., 0] * (-polys[..., 1]) - e[..., 1] * (-polys[..., 0])
    valid = np.hypot(e[..., 0], e[..., 1]) > 1e-12
    pos = ((cross >= 0) | ~valid).all(axis=1)
    neg = ((cross <= 0) | ~valid).all(axis=1)
    return pos | neg


def _overlapping_pairs(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs i < j whose image boxes overlap (by sweeping over sorted left edges)."""
    order = np.argsort(boxes[:, 0], kind="stable")
    b = boxes[order]
    ii_list, jj_list = [], []
    right_sorted = b[:, 2]
    # for each box, candidates are the later boxes whose left edge is left of its right edge
    ends = np.searchsorted(b[:, 0], right_sorted, side="right")
    for k in range(len(b)):
        e = ends[k]
        if e <= k + 1:
            continue
        cand = np.arange(k + 1, e)
        m = (b[cand, 1] <= b[k, 3]) & (b[cand, 3] >= b[k, 1])
        if m.any():
            sel = cand[m]
            ii_list.append(np.full(len(sel), order[k]))
            jj_list.append(order[sel])
    if not ii_list:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(ii_list), np.concatenate(jj_list)


def _toposort(n: int, src: np.ndarray, dst: np.ndarray, key: np.ndarray) -> list[int]:
    """Kahn's algorithm, farthest-first among the ready nodes; cycles broken by the farthest node."""
    indeg = np.bincount(dst, minlength=n).astype(np.int64)
    order_e = np.argsort(src, kind="stable")
    src_s, dst_s = src[order_e], dst[order_e]
    starts = np.searchsorted(src_s, np.arange(n + 1))
    heap = [(-float(key[i]), i) for i in range(n) if indeg[i] == 0]
    heapq.heapify(heap)
    done = np.zeros(n, dtype=bool)
    out: list[int] = []
    remaining = sorted(range(n), key=lambda i: -float(key[i]))
    ptr = 0
    while len(out) < n:
        if not heap:
            while done[remaining[ptr]]:
                ptr += 1
            heap.append((-float(key[remaining[ptr]]), remaining[ptr]))
            indeg[remaining[ptr]] = 0
        _, i = heapq.heappop(heap)
        if done[i]:
            continue
        done[i] = True
        out.append(i)
        for j in dst_s[starts[i]:starts[i + 1]].tolist():
            indeg[j] -= 1
            if indeg[j] == 0 and not done[j]:
                heapq.heappush(heap, (-float(key[j]), j))
    return out
