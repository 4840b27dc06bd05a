"""The metric world model of a synthetic scene: ground regions, solids, tree crowns, sun, footprints.

World frame of ``el.geometry.camera``: metres, x right, y forward, z up, the camera above the origin.
The world does not depend on the camera pose: ``assurance.scenes.renderer.render(world, geometry)`` draws it
from any pose. The forbidden ground footprints (roads, cars, buildings) are kept as polygons so
that the true metric clearance of any ground point can be computed, from the world or from the
scene's meta file alone, including the parts hidden under trees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from assurance.scenes.geom import PolygonSet, clip_to_box, rect
from el.classes.labels import CLASS_IDS

RGB = tuple[float, float, float]
FOOTPRINT_CLASSES: tuple[str, ...] = ("road", "building", "static_car", "moving_car")


@dataclass(frozen=True)
class Look:
    """Appearance of a surface: shader material name, base colour, optional cell colour and cell grid.

    ``cell`` overrides the material's cell grid as (size_u, size_v, half_u, half_v) in metres and
    fractions (windows of a facade, pavers of a plaza); ``cell_rgb`` is the colour inside cells.
    """

    material: str
    rgb: RGB
    cell_rgb: RGB | None = None
    cell: tuple[float, float, float, float] | None = None


@dataclass
class Region:
    """A flat ground area (one or more polygons sharing label and look), drawn in ``layer`` order."""

    polygons: list[np.ndarray]
    label: int
    look: Look
    layer: int


@dataclass
class Block:
    """A box on the ground or on another solid, optionally with a gable roof (ridge along ``w``).

    Centre (cx, cy), size w (along ``angle``) x l, base height z0, wall height h, ridge rise
    ``gable`` above the walls. Buildings, rooftop equipment, car bodies and cabins, people,
    hedges, tree trunks and street furniture are all blocks.
    """

    cx: float
    cy: float
    w: float
    l: float
    angle: float
    z0: float
    h: float
    label: int
    top: Look
    side: Look
    gable: float = 0.0
    kind: str = "solid"
    taper: tuple[float, float] = (1.0, 1.0)  # top size relative to the base, along w and l

    @property
    def top_z(self) -> float:
        return self.z0 + self.h + self.gable

    def footprint(self) -> np.ndarray:
        return rect(self.cx, self.cy, self.w, self.l, self.angle)


@dataclass
class Crown:
    """A tree or bush crown: a cluster of ellipsoid blobs (n, 5) = cx, cy, cz, r, rz, with a trunk."""

    blobs: np.ndarray
    label: int
    look: Look

    @property
    def bottom_z(self) -> float:
        return float((self.blobs[:, 2] - self.blobs[:, 4]).min())

    @property
    def top_z(self) -> float:
        return float((self.blobs[:, 2] + self.blobs[:, 4]).max())


@dataclass(frozen=True)
class Sun:
    """Sun direction: azimuth (deg, clockwise from +y forward toward +x) and elevation above the horizon."""

    azimuth_deg: float
    elevation_deg: float

    def vector(self) -> np.ndarray:
        """Unit vector pointing toward the sun (x, y, z)."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])


@dataclass
class World:
    """Everything a scene holds, in metres; pose-independent."""

    seed: int
    style: str
    lighting: str
    sun: Sun
    grid_angle_deg: float = 0.0
    regions: list[Region] = field(default_factory=list)
    blocks: list[Block] = field(default_factory=list)
    crowns: list[Crown] = field(default_factory=list)
    footprints: dict[str, list[np.ndarray]] = field(default_factory=lambda: {k: [] for k in FOOTPRINT_CLASSES})
    domain: np.ndarray | None = None  # polygon where the city is modelled
    grade: dict[str, float] = field(default_factory=dict)  # per-scene camera/colour grading
    _clearance_sets: dict[tuple[str, ...], PolygonSet] = field(default_factory=dict, repr=False)

    # -- building the world ---------------------------------------------------------------
    def add_region(self, polygons: list[np.ndarray] | np.ndarray, label: int, look: Look, layer: int,
                   *, footprint: bool = True) -> None:
        """Add a ground region; a road region's polygons become road footprints (unless footprint=False)."""
        if isinstance(polygons, np.ndarray):
            polygons = [polygons]
        polys = [np.asarray(p, dtype=np.float64) for p in polygons if len(p) >= 3]
        if not polys:
            return
        self.regions.append(Region(polys, label, look, layer))
        if footprint and label == CLASS_IDS["road"]:
            self.footprints["road"].extend(polys)
        self._clearance_sets.clear()

    def add_block(self, block: Block, *, register: bool | None = None) -> Block:
        """Add a solid; a forbidden one standing on the ground adds its footprint (``register`` forces it)."""
        self.blocks.append(block)
        name = _LABEL_NAMES.get(block.label)
        if register is None:
            register = block.z0 <= 0.05
        if name in self.footprints and register:
            self.footprints[name].append(block.footprint())
            self._clearance_sets.clear()
        return block

    def add_crown(self, crown: Crown) -> None:
        self.crowns.append(crown)

    # -- metric clearance -------------------------------------------------------------------
    def clearance_m(self, x: np.ndarray | float, y: np.ndarray | float,
                    classes: tuple[str, ...] = FOOTPRINT_CLASSES) -> np.ndarray:
        """True distance (m) from ground points to the nearest footprint of ``classes`` (0 inside one)."""
        key = tuple(classes)
        if key not in self._clearance_sets:
            unknown = set(key) - set(FOOTPRINT_CLASSES)
            if unknown:
                raise ValueError(f"unknown footprint classes {sorted(unknown)}; known: {FOOTPRINT_CLASSES}")
            polys = [p for c in key for p in self.footprints[c]]
            self._clearance_sets[key] = PolygonSet(polys)
        return self._clearance_sets[key].distance(np.asarray(x, float), np.asarray(y, float))

    # -- meta round trip ----------------------------------------------------------------------
    def footprints_meta(self, region: tuple[float, float, float, float] | None = None) -> dict[str, Any]:
        """Forbidden footprints as JSON-ready lists of [[x, y], ...] (mm precision).

        With ``region`` = (xmin, xmax, ymin, ymax), only footprints meeting it are kept; the
        clearance is then exact for points whose nearest footprint lies in it.
        """
        out: dict[str, Any] = {}
        for name in FOOTPRINT_CLASSES:
            polys = []
            for p in self.footprints[name]:
                if region is not None and len(clip_to_box(p, *region)) == 0:
                    continue
                polys.append(np.round(p, 3).tolist())
            out[name] = polys
        return out

    @classmethod
    def from_meta(cls, meta: dict[str, Any]) -> World:
        """A footprint-only world from a scene's meta dict: enough for ``clearance_m``."""
        try:
            fp = meta["footprints"]
            sun = meta.get("sun", {"azimuth_deg": 0.0, "elevation_deg": 45.0})
            world = cls(seed=int(meta.get("seed", 0)), style=str(meta.get("style", "")),
                        lighting=str(meta.get("lighting", "")),
                        sun=Sun(float(sun["azimuth_deg"]), float(sun["elevation_deg"])))
            for name in FOOTPRINT_CLASSES:
                world.footprints[name] = [np.asarray(p, dtype=np.float64) for p in fp.get(name, [])]
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"meta has no usable 'footprints' ({exc})") from None
        return world


_LABEL_NAMES = {CLASS_IDS[n]: n for n in FOOTPRINT_CLASSES}


def pixel_clearance_m(world: World, geometry: Any, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """True clearance (m) of pixels (cols, rows): where each pixel's ray meets the ground, to the
    nearest road / car / building footprint. NaN for rays that miss the ground."""
    x, y = geometry.pixel_to_ground(np.asarray(cols, float), np.asarray(rows, float))
    return world.clearance_m(x, y)
