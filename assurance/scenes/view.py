"""What part of the ground a camera sees, and the domain a world must model for a pose envelope."""

from __future__ import annotations

import itertools
import math

import numpy as np

from assurance.scenes.geom import convex_hull
from el.geometry.camera import CameraGeometry, Pose

MAX_RANGE_M = 1500.0  # rays above the horizon are cut here


def visible_ground(geometry: CameraGeometry, *, samples: int = 9) -> np.ndarray:
    """Polygon (k, 2) of the ground seen by the image (its border mapped to the ground, far side capped)."""
    w, h = geometry.width, geometry.height
    t = np.linspace(0, 1, samples)
    cols = np.concatenate([t * w - 0.5, np.full(samples, w - 0.5), (1 - t) * w - 0.5, np.full(samples, -0.5)])
    rows = np.concatenate([np.full(samples, -0.5), t * h - 0.5, np.full(samples, h - 0.5), (1 - t) * h - 0.5])
    x, y = geometry.pixel_to_ground(cols, rows)
    bad = ~np.isfinite(x) | (np.hypot(x, y) > MAX_RANGE_M)
    if bad.any():
        # cap rays that miss the ground (or nearly) at the maximum range along their direction
        hx = cols - w / 2 + 0.5
        x = np.where(bad, np.sign(hx) * np.minimum(np.abs(hx) / geometry.f_px * MAX_RANGE_M, MAX_RANGE_M), x)
        y = np.where(bad, MAX_RANGE_M, y)
    return np.stack([x, y], axis=1)


def coverage_domain(geometry: CameraGeometry, *, rel: float = 0.2, margin_m: float = 20.0) -> np.ndarray:
    """Convex polygon holding the ground seen from every pose with height and pitch within +-rel.

    The world is generated over this domain so that the same world can be rendered from perturbed
    poses (the requirement tests use +-20%) with every visible pixel modelled (ranges are capped
    at twice the nominal view's; beyond, only the base ground). ValueError when the nominal pose
    sees the horizon.
    """
    pose = geometry.pose
    top_depression = math.degrees(float(geometry.depression(-0.5)))
    if top_depression < 3.0:
        raise ValueError(f"pose height {pose.height_m} m, pitch {pose.pitch_deg} deg sees the horizon (top edge "
                         f"{top_depression:.1f} deg below it); the generator models the ground only: raise the pitch")
    nominal = visible_ground(geometry)
    far = 2.0 * float(np.hypot(nominal[:, 0], nominal[:, 1]).max())
    pts = []
    for hf, pf in itertools.product((1 - rel, 1.0, 1 + rel), repeat=2):
        g = CameraGeometry(width=geometry.width, height=geometry.height, intrinsics=geometry.intrinsics,
                           pose=Pose(height_m=pose.height_m * hf, pitch_deg=min(90.0, pose.pitch_deg * pf)))
        v = visible_ground(g)
        r = np.hypot(v[:, 0], v[:, 1])
        pts.append(v * np.minimum(1.0, far / np.maximum(r, 1e-9))[:, None])
    hull = convex_hull(np.concatenate(pts))
    centre = hull.mean(axis=0)
    d = hull - centre
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    return centre + d * (1 + margin_m / np.maximum(norm, 1e-9))
