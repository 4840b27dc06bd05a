"""Generation state of a synthetic city: the world being built, the RNG, the style, the rotated
local street frame (a, b) and the occupancy grids that keep objects apart; and the ground layers.
"""

from __future__ import annotations

import math

import numpy as np

from assurance.scenes.geom import PolygonSet, frame_rect
from assurance.scenes.rand import Rand
from assurance.scenes.styles import Style
from assurance.scenes.world import World

# ground drawing order
L_BASE, L_BLOCK, L_DETAIL, L_DETAIL2, L_LOT_PAINT = 0, 1, 2, 3, 4
L_SIDEWALK, L_CURB, L_VERGE, L_ROAD, L_PATCH, L_MARKING = 5, 6, 7, 8, 9, 10


class Builder:
    """Generation state: the world being built, the RNG, the style, the local frame and occupancy."""

    def __init__(self, world: World, rng: Rand, style: Style, domain: np.ndarray) -> None:
        self.world, self.rng, self.style, self.palette = world, rng, style, style.palette
        self.domain = domain
        self._domain_set = PolygonSet([domain])
        phi = float(rng.uniform(0, math.pi / 2))
        world.grid_angle_deg = math.degrees(phi)
        self.phi = phi
        self.ea = np.array([math.cos(phi), math.sin(phi)])
        self.eb = np.array([-math.sin(phi), math.cos(phi)])
        self.origin = np.array([rng.uniform(-60, 60), rng.uniform(0, 120)])
        loc = (domain - self.origin) @ np.stack([self.ea, self.eb], axis=1)
        self.amin, self.bmin = loc.min(axis=0) - 5
        self.amax, self.bmax = loc.max(axis=0) + 5
        self.res = 0.5
        self._a0, self._b0 = self.amin - 80, self.bmin - 80
        shape = (int((self.bmax - self._b0 + 80) / self.res) + 1, int((self.amax - self._a0 + 80) / self.res) + 1)
        self.solid = np.zeros(shape, dtype=bool)
        self.buildings = np.zeros(shape, dtype=bool)

    # -- frames -------------------------------------------------------------------------------
    def to_world(self, a: float, b: float) -> tuple[float, float]:
        p = self.origin + a * self.ea + b * self.eb
        return float(p[0]), float(p[1])

    def to_local(self, x: float, y: float) -> tuple[float, float]:
        d = np.array([x, y]) - self.origin
        return float(d @ self.ea), float(d @ self.eb)

    def rect(self, a0: float, a1: float, b0: float, b1: float) -> np.ndarray:
        """World polygon of the local rectangle [a0, a1] x [b0, b1]."""
        return frame_rect(self.origin, self.ea, self.eb, a0, a1, b0, b1)

    def in_domain(self, a0: float, a1: float, b0: float, b1: float, margin: float = 0.0) -> bool:
        """Whether a local rectangle comes within ``margin`` of the modelled domain."""
        ca, cb = (a0 + a1) / 2, (b0 + b1) / 2
        x, y = self.to_world(ca, cb)
        half = math.hypot(a1 - a0, b1 - b0) / 2
        return float(self._domain_set.distance(np.array([x]), np.array([y]))[0]) <= half + margin

    # -- occupancy ----------------------------------------------------------------------------
    def _cells(self, a0: float, a1: float, b0: float, b1: float) -> tuple[slice, slice]:
        i0 = max(0, int((b0 - self._b0) / self.res))
        i1 = max(0, int(math.ceil((b1 - self._b0) / self.res)))
        j0 = max(0, int((a0 - self._a0) / self.res))
        j1 = max(0, int(math.ceil((a1 - self._a0) / self.res)))
        return slice(i0, i1), slice(j0, j1)

    def occupy_local(self, a0: float, a1: float, b0: float, b1: float, *, building: bool = False) -> None:
        sl = self._cells(a0, a1, b0, b1)
        self.solid[sl] = True
        if building:
            self.buildings[sl] = True

    def occupy_rect_world(self, cx: float, cy: float, w: float, l: float, angle: float, *,
                          building: bool = False) -> None:
        a, b = self.to_local(cx, cy)
        rel = angle - self.phi
        ha = abs(math.cos(rel)) * w / 2 + abs(math.sin(rel)) * l / 2
        hb = abs(math.sin(rel)) * w / 2 + abs(math.cos(rel)) * l / 2
        self.occupy_local(a - ha, a + ha, b - hb, b + hb, building=building)

    def occupy_circle_world(self, x: float, y: float, r: float) -> None:
        a, b = self.to_local(x, y)
        self.occupy_local(a - r, a + r, b - r, b + r)

    def free_local(self, a: float, b: float, r: float, *, buildings_only: bool = False) -> bool:
        sl = self._cells(a - r, a + r, b - r, b + r)
        grid = self.buildings if buildings_only else self.solid
        return not grid[sl].any()

    def free_rect_local(self, a0: float, a1: float, b0: float, b1: float) -> bool:
        """Whether nothing solid occupies the local rectangle [a0, a1] x [b0, b1]."""
        return not self.solid[self._cells(a0, a1, b0, b1)].any()

    def free_world(self, x: float, y: float, r: float, *, buildings_only: bool = False) -> bool:
        a, b = self.to_local(x, y)
        return self.free_local(a, b, r, buildings_only=buildings_only)

    # -- helpers used by block fillers ----------------------------------------------------------
    def strip_across(self, a0: float, a1: float, b0: float, b1: float,
                     width: float) -> tuple[float, float, float, float]:
        """Local rectangle of a straight strip of ``width`` crossing the block along a or b."""
        if self.rng.random() < 0.5:
            c = float(self.rng.uniform(b0 + width, b1 - width))
            return a0, a1, c - width / 2, c + width / 2
        c = float(self.rng.uniform(a0 + width, a1 - width))
        return c - width / 2, c + width / 2, b0, b1
