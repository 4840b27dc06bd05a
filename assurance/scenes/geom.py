"""Planar polygon helpers in metres: shapes, clipping, hulls and exact point-to-polygon distances.

Polygons are float64 arrays of shape (k, 2) holding (x, y) vertices in order (either winding).
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def rect(cx: float, cy: float, w: float, l: float, angle: float) -> np.ndarray:
    """Rectangle centred on (cx, cy), width ``w`` along the direction ``angle`` (rad), length ``l`` across it."""
    c, s = math.cos(angle), math.sin(angle)
    u = np.array([c, s]) * (w / 2)
    v = np.array([-s, c]) * (l / 2)
    centre = np.array([cx, cy])
    return np.array([centre - u - v, centre + u - v, centre + u + v, centre - u + v])


def frame_rect(origin: np.ndarray, ea: np.ndarray, eb: np.ndarray, a0: float, a1: float,
               b0: float, b1: float) -> np.ndarray:
    """Rectangle [a0, a1] x [b0, b1] of a rotated frame (origin, unit axes ea, eb) in world coordinates."""
    corners = np.array([[a0, b0], [a1, b0], [a1, b1], [a0, b1]], dtype=np.float64)
    return origin + corners[:, :1] * ea + corners[:, 1:] * eb


def ellipse(cx: float, cy: float, rx: float, ry: float, angle: float = 0.0, n: int = 16,
            jitter: np.ndarray | None = None) -> np.ndarray:
    """Polygon of ``n`` vertices on an ellipse; ``jitter`` (n,) scales each radius for blobby shapes."""
    t = np.linspace(0, 2 * math.pi, n, endpoint=False)
    r = np.ones(n) if jitter is None else jitter
    px, py = rx * r * np.cos(t), ry * r * np.sin(t)
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([cx + c * px - s * py, cy + s * px + c * py], axis=1)


def clip_to_box(poly: np.ndarray, xmin: float, xmax: float, ymin: float, ymax: float) -> np.ndarray:
    """Sutherland-Hodgman clip of a polygon to an axis-aligned box; may return an empty (0, 2) array."""
    out = np.asarray(poly, dtype=np.float64)
    lo, hi = out.min(axis=0), out.max(axis=0)
    if lo[0] >= xmin and hi[0] <= xmax and lo[1] >= ymin and hi[1] <= ymax:
        return out
    if hi[0] < xmin or lo[0] > xmax or hi[1] < ymin or lo[1] > ymax:
        return np.zeros((0, 2))
    for axis, bound, keep_greater in ((0, xmin, True), (0, xmax, False), (1, ymin, True), (1, ymax, False)):
        if len(out) == 0:
            break
        coord = out[:, axis]
        inside = coord >= bound if keep_greater else coord <= bound
        if inside.all():
            continue
        if not inside.any():
            return np.zeros((0, 2))
        nxt = np.roll(out, -1, axis=0)
        nxt_inside = np.roll(inside, -1)
        pts: list[np.ndarray] = []
        for p, q, pin, qin in zip(out, nxt, inside, nxt_inside, strict=True):
            if pin:
                pts.append(p)
            if pin != qin:
                t = (bound - p[axis]) / (q[axis] - p[axis])
                pts.append(p + t * (q - p))
        out = np.array(pts) if pts else np.zeros((0, 2))
    return out


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (k, 2) of a point set, counter-clockwise in a y-up frame."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 1, 2)
    hull = cv2.convexHull(pts, clockwise=False).reshape(-1, 2).astype(np.float64)
    return hull


def _segments(polygons: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All edges (S, 4) as x1, y1, x2, y2 and the index of the polygon each belongs to."""
    segs, owner = [], []
    for i, p in enumerate(polygons):
        p = np.asarray(p, dtype=np.float64)
        q = np.roll(p, -1, axis=0)
        segs.append(np.concatenate([p, q], axis=1))
        owner.append(np.full(len(p), i))
    if not segs:
        return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
    return np.concatenate(segs), np.concatenate(owner)


def _point_segment_distance(px: np.ndarray, py: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances (n, m) from n points to m segments."""
    x1, y1, x2, y2 = (segs[:, i][None, :] for i in range(4))
    dx, dy = x2 - x1, y2 - y1
    len2 = np.maximum(dx * dx + dy * dy, 1e-18)
    t = np.clip(((px[:, None] - x1) * dx + (py[:, None] - y1) * dy) / len2, 0.0, 1.0)
    ex = px[:, None] - (x1 + t * dx)
    ey = py[:, None] - (y1 + t * dy)
    return np.sqrt(ex * ex + ey * ey)


class PolygonSet:
    """A set of polygons answering exact distance and containment queries for many points at once.

    ``distance(x, y)`` is 0 inside any polygon and the Euclidean distance to the nearest edge
    outside. Queries are bucketed on a square tile grid so that each tile only meets the edges
    that can be nearest to it: exact, and fast for dense pixel grids.
    """

    def __init__(self, polygons: list[np.ndarray], *, tile_m: float = 8.0) -> None:
        self.polygons = [np.asarray(p, dtype=np.float64) for p in polygons if len(p) >= 3]
        self.segments, self.owner = _segments(self.polygons)
        self.tile_m = tile_m
        if self.polygons:
            self.bboxes = np.array([[p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max()]
                                    for p in self.polygons])
        else:
            self.bboxes = np.zeros((0, 4))

    def __len__(self) -> int:
        return len(self.polygons)

    def _inside(self, px: np.ndarray, py: np.ndarray, poly_ids: np.ndarray) -> np.ndarray:
        """True where a point lies inside any of the given polygons (even-odd rule per polygon)."""
        seg_sel = np.flatnonzero(np.isin(self.owner, poly_ids))
        segs = self.segments[seg_sel]
        x1, y1, x2, y2 = (segs[:, i][None, :] for i in range(4))
        yy = py[:, None]
        straddle = (y1 > yy) != (y2 > yy)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x1 + (yy - y1) * (x2 - x1) / (y2 - y1)
        cross = (straddle & (px[:, None] < xc)).astype(np.int32)
        owners = self.owner[seg_sel]
        starts = np.flatnonzero(np.r_[True, owners[1:] != owners[:-1]])
        per_poly = np.add.reduceat(cross, starts, axis=1)
        return ((per_poly % 2) == 1).any(axis=1)

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Boolean array: point inside any polygon."""
        return self.distance(x, y) == 0.0

    def distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Exact distance (m) from points to the union of the polygons; 0 inside, +inf if the set is empty."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        shape = np.broadcast_shapes(x.shape, y.shape)
        px = np.broadcast_to(x, shape).ravel()
        py = np.broadcast_to(y, shape).ravel()
        out = np.full(px.shape, np.inf)
        finite = np.isfinite(px) & np.isfinite(py)
        if not self.polygons or not finite.any():
            out[~finite] = np.nan
            return out.reshape(shape)
        idx_all = np.flatnonzero(finite)
        t = self.tile_m
        tx = np.floor(px[idx_all] / t).astype(np.int64)
        ty = np.floor(py[idx_all] / t).astype(np.int64)
        key = (tx - tx.min()) * (int(ty.max() - ty.min()) + 1) + (ty - ty.min())
        order = np.argsort(key, kind="stable")
        keys_sorted = key[order]
        starts = np.flatnonzero(np.r_[True, keys_sorted[1:] != keys_sorted[:-1]])
        ends = np.r_[starts[1:], len(order)]
        half_diag = t * math.sqrt(0.5)
        segs = self.segments
        for s, e in zip(starts, ends, strict=True):
            sel = idx_all[order[s:e]]
            qx, qy = px[sel], py[sel]
            cx = (math.floor(qx[0] / t) + 0.5) * t
            cy = (math.floor(qy[0] / t) + 0.5) * t
            dc = _point_segment_distance(np.array([cx]), np.array([cy]), segs)[0]
            bound = dc.min() + 2 * half_diag + 1e-9
            cand = np.flatnonzero(dc <= bound)
            d = _point_segment_distance(qx, qy, segs[cand]).min(axis=1)
            # containment: only polygons whose bbox meets the tile can hold its points
            bb = self.bboxes
            hit = np.flatnonzero((bb[:, 0] <= cx + t / 2) & (bb[:, 2] >= cx - t / 2)
                                 & (bb[:, 1] <= cy + t / 2) & (bb[:, 3] >= cy - t / 2))
            if len(hit):
                d[self._inside(qx, qy, hit)] = 0.0
            out[sel] = d
        out[~finite] = np.nan
        return out.reshape(shape)
