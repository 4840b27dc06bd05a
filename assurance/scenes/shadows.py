"""Sun shadows: ground shadow polygons, roof shadows, and whether a 3D point sees the sun.

Shadows on the ground are exact polygons (the hull of a solid's vertices projected along the sun
onto the ground); a flat roof receives the shadows of taller neighbours the same way on its own
plane. Everything else (cars, people, walls, crowns) is lit or shaded as a whole, by casting one
ray toward the sun against the boxes and crown blobs around it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from assurance.scenes.world import World


def unit_sphere(n_lat: int = 5, n_lon: int = 10) -> np.ndarray:
    """Sample points on the unit sphere (poles included), (m, 3)."""
    lat = np.linspace(-np.pi / 2, np.pi / 2, n_lat)
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat[1:-1], lon, indexing="ij")
    pts = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1).reshape(-1, 3)
    return np.concatenate([pts, [[0, 0, 1], [0, 0, -1]]])


def project_to_plane(points: np.ndarray, sun: np.ndarray, z: float = 0.0) -> np.ndarray:
    """Project 3D points (..., 3) along the sun direction onto the horizontal plane at height z: (..., 2)."""
    k = (points[..., 2] - z) / sun[2]
    return points[..., :2] - k[..., None] * sun[:2]


@dataclass
class Casters:
    """Boxes and crown blobs that can shade others, as arrays."""

    boxes: np.ndarray  # (m, 8): cx, cy, cos, sin, half_w, half_l, z0, z1
    box_owner: np.ndarray  # (m,) block index
    blobs: np.ndarray  # (k, 5): cx, cy, cz, r, rz
    blob_owner: np.ndarray  # (k,) crown index

    @classmethod
    def from_world(cls, world: World, bbox: tuple[float, float, float, float], *, min_height: float = 2.5,
                   crown_labels: tuple[int, ...] = ()) -> Casters:
        """Solids taller than ``min_height`` and crowns with the given labels near ``bbox`` (xmin, xmax, ymin, ymax)."""
        xmin, xmax, ymin, ymax = bbox
        rows, owners = [], []
        for i, b in enumerate(world.blocks):
            if b.top_z - b.z0 < min_height and b.z0 < 0.5:
                continue
            if not (xmin - 30 <= b.cx <= xmax + 30 and ymin - 30 <= b.cy <= ymax + 30):
                continue
            rows.append((b.cx, b.cy, np.cos(b.angle), np.sin(b.angle), b.w / 2, b.l / 2, b.z0,
                         b.z0 + b.h + 0.5 * b.gable))
            owners.append(i)
        blobs, bown = [], []
        for i, c in enumerate(world.crowns):
            if c.label not in crown_labels:
                continue
            if not (xmin - 30 <= c.blobs[0, 0] <= xmax + 30 and ymin - 30 <= c.blobs[0, 1] <= ymax + 30):
                continue
            blobs.append(c.blobs)
            bown.extend([i] * len(c.blobs))
        return cls(np.array(rows, dtype=np.float64).reshape(-1, 8), np.array(owners, dtype=np.int64),
                   np.concatenate(blobs) if blobs else np.zeros((0, 5)), np.array(bown, dtype=np.int64))

    def occlusion(self, points: np.ndarray, sun: np.ndarray, *, own_block: np.ndarray | None = None,
                  own_crown: np.ndarray | None = None, crown_density: float = 0.75,
                  chunk: int = 512) -> np.ndarray:
        """Shadow amount in [0, 1] at points (N, 3): 1 behind a box, ``crown_density`` behind foliage."""
        n = len(points)
        out = np.zeros(n, dtype=np.float32)
        own_block = np.full(n, -1) if own_block is None else own_block
        own_crown = np.full(n, -1) if own_crown is None else own_crown
        for s in range(0, n, chunk):
            p = points[s:s + chunk]
            ob, oc = own_block[s:s + chunk], own_crown[s:s + chunk]
            hit = np.zeros(len(p), dtype=np.float32)
            if len(self.boxes):
                hit = np.maximum(hit, self._hit_boxes(p, sun, ob).astype(np.float32))
            if len(self.blobs):
                hit = np.maximum(hit, crown_density * self._hit_blobs(p, sun, oc).astype(np.float32))
            out[s:s + chunk] = hit
        return out

    def _hit_boxes(self, p: np.ndarray, sun: np.ndarray, own: np.ndarray) -> np.ndarray:
        bx = self.boxes
        dx = p[:, None, 0] - bx[None, :, 0]
        dy = p[:, None, 1] - bx[None, :, 1]
        c, s = bx[None, :, 2], bx[None, :, 3]
        pu, pv = c * dx + s * dy, -s * dx + c * dy
        du, dv = c * sun[0] + s * sun[1], -s * sun[0] + c * sun[1]
        t_enter = np.zeros(pu.shape)
        t_exit = np.full(pu.shape, np.inf)
        for pos, d, lo, hi in ((pu, du, -bx[None, :, 4], bx[None, :, 4]), (pv, dv, -bx[None, :, 5], bx[None, :, 5])):
            with np.errstate(divide="ignore", invalid="ignore"):
                t1 = (lo - pos) / d
                t2 = (hi - pos) / d
            flat = np.abs(d) < 1e-12
            inside = (pos >= lo) & (pos <= hi)
            t_lo = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
            t_hi = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
            t_enter = np.maximum(t_enter, t_lo)
            t_exit = np.minimum(t_exit, t_hi)
        tz1 = (bx[None, :, 6] - p[:, None, 2]) / sun[2]
        tz2 = (bx[None, :, 7] - p[:, None, 2]) / sun[2]
        t_enter = np.maximum(t_enter, tz1)
        t_exit = np.minimum(t_exit, tz2)
        hit = (t_exit > t_enter) & (t_exit > 1e-3)
        hit &= self.box_owner[None, :] != own[:, None]
        return hit.any(axis=1)

    def _hit_blobs(self, p: np.ndarray, sun: np.ndarray, own: np.ndarray) -> np.ndarray:
        bl = self.blobs
        scale = bl[None, :, 3] / bl[None, :, 4]
        ox = p[:, None, 0] - bl[None, :, 0]
        oy = p[:, None, 1] - bl[None, :, 1]
        oz = (p[:, None, 2] - bl[None, :, 2]) * scale
        dz = sun[2] * scale
        a = sun[0] ** 2 + sun[1] ** 2 + dz * dz
        bq = ox * sun[0] + oy * sun[1] + oz * dz
        cq = ox * ox + oy * oy + oz * oz - bl[None, :, 3] ** 2
        disc = bq * bq - a * cq
        hit = (disc > 0) & ((-bq + np.sqrt(np.maximum(disc, 0))) > 1e-3)
        hit &= self.blob_owner[None, :] != own[:, None]
        return hit.any(axis=1)
