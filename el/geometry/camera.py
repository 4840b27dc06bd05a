"""Pinhole camera over a flat ground plane: pixel footprints, safety radius in pixels, pixel <-> ground.

docs/architecture.md section 2.2. World frame: origin on the ground below the camera, x to the right of the
image, y forward (the direction the camera looks), z up. Image rows count from the top,
columns from the left; pixel centres sit at half-integers of the sensor grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

NUM_STRIPES = 10  # horizontal stripes of equal height: the unit of reachability (and of radii in "paper" mode)
UNREACHABLE_STRIPES = 2  # the paper's count at its shipped pose; the flight code derives it per pose (reach_m)
REACH_M = 90.0
"""Default reach (m): ground farther ahead of the nadir point is out of reach. Phantom 4 at 50 m, 45 degrees:
the top rows of stripes 1 and 2 see the ground 100.9 m and 83.9 m ahead at 3840x2160 (100.6-101.5 m and
83.7-84.0 m at 1024x576 down to 256x144), so 90 m, a round value between them, drops exactly the paper's
top 2 stripes at every size."""
REACH_BOUNDS_M = (1.0, 10_000.0)


# Bounds of what the flat-ground pinhole model is stated for (docs/architecture.md section 2.2).
SENSOR_MM = (1.0, 100.0)  # sensor width / height: from phone sensors to medium format
FOCAL_MM = (0.5, 2000.0)
HFOV_DEG = (5.0, 120.0)  # beyond 120 degrees a lens is a fisheye the pinhole model does not describe
HEIGHT_M = (1.0, 500.0)
PITCH_DEG = (5.0, 90.0)
MAX_ROLL_DEG = 5.0  # a larger roll is refused (check_geometry); up to it the pose-error box absorbs it
MIN_DEPRESSION_DEG = 3.0  # every reachable row looks at least this far below the horizon
FOV_SENSOR_WIDTH_MM = 36.0  # sensor width recorded for a camera given by its field of view (35 mm equivalent)


def check_number(name: str, value: object, lo: float, hi: float, unit: str = "") -> float:
    """``value`` as a float when it is a finite number in [lo, hi]; ValueError naming name, value and range."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name} must be a number in [{lo:g}, {hi:g}]{unit}, got {value!r}")
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{name} must lie in [{lo:g}, {hi:g}]{unit}, got {value!r}")
    return float(value)


@dataclass(frozen=True, kw_only=True)
class Intrinsics:
    """Lens and sensor. Defaults: DJI Phantom 4 (13.2 mm wide sensor, 8.8 mm focal length).

    Pixels are square and the image is the sensor's largest centred crop of its aspect ratio: it spans
    the sensor's full width, or, when ``sensor_height_mm`` is given and the image is taller than the
    sensor's proportions, its full height (``focal_px``). Without a sensor height the image spans the width.
    """

    sensor_width_mm: float = 13.2
    focal_mm: float = 8.8
    name: str = "phantom4"
    sensor_height_mm: float | None = None

    def __post_init__(self) -> None:
        check_number("sensor_width_mm", self.sensor_width_mm, *SENSOR_MM, " mm")
        check_number("focal_mm", self.focal_mm, *FOCAL_MM, " mm")
        if self.sensor_height_mm is not None:
            check_number("sensor_height_mm", self.sensor_height_mm, *SENSOR_MM, " mm")
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"camera name must be a non-empty string, got {self.name!r}")
        lo, hi = HFOV_DEG
        if not lo <= self.hfov_deg <= hi:
            raise ValueError(f"horizontal field of view {self.hfov_deg:.1f} deg (sensor_width_mm "
                             f"{self.sensor_width_mm:g}, focal_mm {self.focal_mm:g}) must lie in [{lo:g}, {hi:g}] deg")

    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view (degrees) across the sensor's width."""
        return math.degrees(2.0 * math.atan(self.sensor_width_mm / (2.0 * self.focal_mm)))

    def focal_px(self, width: int, height: int) -> float:
        """Focal length in pixels of an image of ``width x height`` taken with this camera."""
        sh = self.sensor_height_mm
        if sh is not None and height * self.sensor_width_mm > width * sh:  # taller than the sensor: full height
            return self.focal_mm * height / sh
        return self.focal_mm * width / self.sensor_width_mm

    @classmethod
    def from_fov(cls, hfov_deg: float, *, sensor_width_mm: float = FOV_SENSOR_WIDTH_MM,
                 sensor_height_mm: float | None = None, name: str = "custom") -> Intrinsics:
        """A camera given by its horizontal field of view (the focal length follows from the sensor width)."""
        hfov = check_number("hfov_deg", hfov_deg, *HFOV_DEG, " deg")
        sw = check_number("sensor_width_mm", sensor_width_mm, *SENSOR_MM, " mm")
        return cls(sensor_width_mm=sw, focal_mm=sw / (2.0 * math.tan(math.radians(hfov) / 2.0)), name=name,
                   sensor_height_mm=sensor_height_mm)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; ``sensor_height_mm`` only when set, so the default records as it always did."""
        out: dict[str, Any] = {"sensor_width_mm": self.sensor_width_mm, "focal_mm": self.focal_mm, "name": self.name}
        if self.sensor_height_mm is not None:
            out["sensor_height_mm"] = self.sensor_height_mm
        return out


PHANTOM4 = Intrinsics()
PHANTOM3_PRO = Intrinsics(sensor_width_mm=6.17, focal_mm=3.61, name="phantom3pro")
CAMERAS: dict[str, Intrinsics] = {c.name: c for c in (PHANTOM4, PHANTOM3_PRO)}


@dataclass(frozen=True, kw_only=True)
class Pose:
    """Camera height above the ground (m) and pitch below the horizon (degrees), within HEIGHT_M and PITCH_DEG."""

    height_m: float = 50.0
    pitch_deg: float = 45.0

    def __post_init__(self) -> None:
        # ranges only: the flight path's frame_core checks the types of a pose handed in at run time
        for name, (lo, hi), unit in (("height_m", HEIGHT_M, " m"), ("pitch_deg", PITCH_DEG, " degrees")):
            value = getattr(self, name)
            if not (isinstance(value, int | float | np.integer | np.floating) and math.isfinite(value)
                    and lo <= value <= hi):
                raise ValueError(f"{name} must lie in [{lo:g}, {hi:g}]{unit}, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class SafetyParams:
    """Safety radius R (m) and the coefficient beta that absorbs pose errors."""

    radius_m: float = 2.0
    beta: float = 1.7

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"radius_m must be positive, got {self.radius_m!r}")
        if not (math.isfinite(self.beta) and self.beta >= 1.0):
            raise ValueError(f"beta must be >= 1, got {self.beta!r}")


@dataclass(frozen=True, kw_only=True)
class CameraGeometry:
    """The camera model for one image size: per-row pixel footprint and pixel <-> ground maps."""

    width: int
    height: int
    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    pose: Pose = field(default_factory=Pose)
    reach_m: float = REACH_M

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise ValueError(f"image size must be at least 8x8, got {self.width}x{self.height}")
        check_number("reach_m", self.reach_m, *REACH_BOUNDS_M, " m")

    # -- basic quantities -------------------------------------------------------------------
    @property
    def f_px(self) -> float:
        """Focal length in pixels."""
        return self.intrinsics.focal_px(self.width, self.height)

    @property
    def theta(self) -> float:
        return math.radians(self.pose.pitch_deg)

    def row_phi(self, rows: np.ndarray | float) -> np.ndarray:
        """Angle (rad) of the row's ray below the optical axis (negative above the centre)."""
        v = np.asarray(rows, dtype=np.float64) - self.height / 2 + 0.5
        return np.arctan(v / self.f_px)

    def depression(self, rows: np.ndarray | float) -> np.ndarray:
        """Angle (rad) of the row's ray below the horizon."""
        return self.theta + self.row_phi(rows)

    def pixel_size(self, rows: np.ndarray | float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ground size (m) of a centre-column pixel per row: (across, along, delta = min of both).

        Rows whose ray does not reach the ground (at or above the horizon) get +inf.
        """
        if rows is None:
            rows = np.arange(self.height)
        phi = self.row_phi(rows)
        dep = self.theta + phi
        s = np.sin(dep)
        with np.errstate(divide="ignore", invalid="ignore"):
            across = np.where(s > 0, self.pose.height_m * np.cos(phi) / (self.f_px * s), np.inf)
            along = np.where(s > 0, self.pose.height_m * np.cos(phi) ** 2 / (self.f_px * s**2), np.inf)
        return across, along, np.minimum(across, along)

    def radius_px(self, rows: np.ndarray | float | None = None, safety: SafetyParams | None = None) -> np.ndarray:
        """Safety radius in pixels per row, ``beta * R / delta_i``."""
        safety = safety or SafetyParams()
        _, _, delta = self.pixel_size(rows)
        return safety.beta * safety.radius_m / delta

    def ground_distance(self, rows: np.ndarray | float) -> np.ndarray:
        """Horizontal distance (m) from the nadir point to the ground the row's centre column sees; +inf for
        rays at or above the horizon. Rows past the nadir point look back: their distance grows again."""
        dep = self.depression(rows)
        s = np.sin(dep)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(s > 0, self.pose.height_m * np.abs(np.cos(dep)) / s, np.inf)

    @property
    def nadir_y(self) -> float:
        """Image y (continuous coordinates) of the ground right below the camera, where the UAV comes down when
        it opens its parachute without moving: H/2 for a nadir camera, beyond H when out of view (oblique)."""
        return self.height / 2.0 + self.f_px * math.tan(math.radians(90.0 - self.pose.pitch_deg))

    # -- stripes and reachable rows ---------------------------------------------------------
    def stripe_edges(self) -> np.ndarray:
        """Row boundaries of the 10 horizontal stripes, shape (11,)."""
        return np.round(np.linspace(0, self.height, NUM_STRIPES + 1)).astype(int)

    @property
    def unreachable_stripes(self) -> int:
        """How many leading stripes are never landing targets, from the pose and camera (paper: "the sky or
        unreachable areas"): those whose top row looks less than MIN_DEPRESSION_DEG below the horizon or sees
        the ground farther than ``reach_m`` ahead. The shipped 45 degree case gives the paper's 2; a nadir one 0."""
        tops = self.stripe_edges()[:-1] - 0.5  # the upper edge of each stripe's top row: its farthest ground
        far = (np.degrees(self.depression(tops)) < MIN_DEPRESSION_DEG) | ~(self.ground_distance(tops) <= self.reach_m)
        return int(np.argmin(far)) if not far.all() else NUM_STRIPES

    @property
    def first_reachable_row(self) -> int:
        """Rows above this one (the ``unreachable_stripes`` leading stripes) are never landing targets;
        ``height`` when no stripe is within reach."""
        return int(self.stripe_edges()[self.unreachable_stripes])

    def reachable_rows(self) -> np.ndarray:
        """Boolean (height,) mask of rows where a landing point may lie."""
        mask = np.zeros(self.height, dtype=bool)
        mask[self.first_reachable_row :] = True
        return mask

    # -- pixel <-> ground -------------------------------------------------------------------
    def pixel_to_ground(self, cols: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the rays of pixels (cols, rows) meet the ground: (x right, y forward) in metres.

        ``cols`` and ``rows`` are pixel indices whose integer values are pixel centres; a point in
        continuous image coordinates (as in decisions, where pixel c spans [c, c+1)) is index x - 0.5.

        Rays at or above the horizon give NaN.
        """
        h = np.asarray(cols, dtype=np.float64) - self.width / 2 + 0.5
        v = np.asarray(rows, dtype=np.float64) - self.height / 2 + 0.5
        st, ct = math.sin(self.theta), math.cos(self.theta)
        denom = v * ct + self.f_px * st
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(denom > 0, self.pose.height_m / denom, np.nan)
        return t * h, t * (self.f_px * ct - v * st)

    def ground_to_pixel(
        self, x: np.ndarray, y: np.ndarray, z: np.ndarray | float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Project world points (x, y, z) in metres to (col, row) pixel indices (see pixel_to_ground).

        Points behind the camera give NaN.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        dz = np.asarray(z, dtype=np.float64) - self.pose.height_m
        st, ct = math.sin(self.theta), math.cos(self.theta)
        zc = y * ct - dz * st
        yc = -y * st - dz * ct
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(zc > 1e-9, self.f_px / zc, np.nan)
        return x * inv + self.width / 2 - 0.5, yc * inv + self.height / 2 - 0.5

    def camera_to_point_distance(self, x: np.ndarray, y: np.ndarray, z: np.ndarray | float = 0.0) -> np.ndarray:
        """Depth of world points along the optical axis (m): used to order drawing far to near."""
        st, ct = math.sin(self.theta), math.cos(self.theta)
        dz = np.asarray(z, dtype=np.float64) - self.pose.height_m
        return np.asarray(y, dtype=np.float64) * ct - dz * st

    def scaled(self, width: int, height: int) -> CameraGeometry:
        """The same camera and pose for another image size of the same aspect ratio."""
        return CameraGeometry(width=width, height=height, intrinsics=self.intrinsics, pose=self.pose,
                              reach_m=self.reach_m)


def geometry_problem(geometry: CameraGeometry, *, roll_deg: float = 0.0) -> str | None:
    """Why the flat-ground pinhole model cannot plan on this camera, pose and image size; None when it can.

    Every reachable row (below the ``unreachable_stripes``) must look at least ``MIN_DEPRESSION_DEG`` below
    the horizon, so it sees the ground at a finite footprint. The stripes are cut at that angle on the upper
    edge of their top row, so what is left to check is that edge under a roll (from a flight log), which is
    not modelled: up to ``MAX_ROLL_DEG`` it is a pose error, which tilts the rows' depression at the
    image's side edges by at most ``atan(tan(hfov / 2) sin|roll|)``, taken off the margin; beyond, it is
    refused. No reachable row at all (all ground in view beyond ``reach_m``) is fine: no candidate, the default.
    """
    if isinstance(roll_deg, bool) or not isinstance(roll_deg, int | float | np.integer | np.floating) \
            or not math.isfinite(roll_deg) or abs(roll_deg) > MAX_ROLL_DEG:
        return (f"roll_deg must lie in [-{MAX_ROLL_DEG:g}, {MAX_ROLL_DEG:g}] degrees (the flat-ground model plans "
                f"without roll; a larger roll is not a pose error the safety coefficient absorbs), got {roll_deg!r}")
    g = geometry
    half_hfov = math.atan(g.width / 2.0 / g.f_px)
    shift = math.degrees(math.atan(math.tan(half_hfov) * math.sin(math.radians(abs(float(roll_deg))))))
    low = _low_row(g, shift)
    if low is None:
        return None
    row, top = low
    # the pitches that plan need not be one interval (a steeper pitch brings a higher stripe within reach):
    # the least pitch from which every steeper one plans, on a 0.1 degree grid (None: not even a nadir one)
    need: float | None = None
    for tenth in range(int(PITCH_DEG[1] * 10), int(math.floor(g.pose.pitch_deg * 10)), -1):
        steeper = CameraGeometry(width=g.width, height=g.height, intrinsics=g.intrinsics, reach_m=g.reach_m,
                                 pose=Pose(height_m=g.pose.height_m, pitch_deg=tenth / 10.0))
        if _low_row(steeper, shift) is not None:
            break
        need = tenth / 10.0
    allowed = f"{need:.1f}" if need is not None else f"{PITCH_DEG[1]:.1f} (none: narrow the field of view)"
    roll = f", roll {float(roll_deg):g} deg" if roll_deg else ""
    return (f"pose height_m {g.pose.height_m:g}, pitch_deg {g.pose.pitch_deg:g}{roll} with camera "
            f"{g.intrinsics.name!r} (horizontal field of view {math.degrees(2 * half_hfov):.1f} deg) on a "
            f"{g.width}x{g.height} image: reachable row {row} looks {top:.1f} deg below the horizon, the "
            f"flat-ground model needs at least {MIN_DEPRESSION_DEG:g} deg; allowed: pitch_deg >= {allowed}")


def _low_row(g: CameraGeometry, shift: float) -> tuple[int, float] | None:
    """(first reachable row, degrees its upper edge looks below the horizon less a roll's ``shift``) when that
    is under MIN_DEPRESSION_DEG; None when it is not (every row below looks farther down: a finite footprint)."""
    row = g.first_reachable_row
    if row >= g.height:
        return None
    top = math.degrees(float(g.depression(row - 0.5))) - shift
    return (row, top) if top < MIN_DEPRESSION_DEG else None


def check_geometry(geometry: CameraGeometry, *, roll_deg: float = 0.0) -> None:
    """ValueError (naming the value and what is allowed) when ``geometry_problem`` finds one."""
    problem = geometry_problem(geometry, roll_deg=roll_deg)
    if problem:
        raise ValueError(problem)


def working_size(width: int, height: int, working_width: int = 1024) -> tuple[int, int]:
    """Working (low) resolution that keeps the aspect ratio: (1024, round(1024 * H / W))."""
    return working_width, int(round(working_width * height / width))


def required_beta(
    geometry: CameraGeometry,
    *,
    height_error: float = 0.2,
    pitch_error: float = 0.2,
    steps: int = 21,
) -> float:
    """Smallest beta that keeps the true safety radius >= R for pose errors in the given box.

    Planning uses the nominal pose; the true height and pitch are each off by up to the given
    relative error. The radius in metres actually covered is ``beta R delta_true / delta_nominal``,
    so beta must reach the worst ratio ``delta_nominal / delta_true`` over the reachable rows and
    the error box (searched on a ``steps x steps`` grid that includes its corners).
    """
    if not (0 <= height_error < 1 and 0 <= pitch_error < 1):
        raise ValueError("relative errors must lie in [0, 1)")
    rows = np.arange(geometry.first_reachable_row, geometry.height)
    if rows.size == 0:  # no stripe within reach: no landing is planned, so no radius is at risk
        return 1.0
    _, _, nominal = geometry.pixel_size(rows)
    worst = 1.0
    for hf in np.linspace(1 - height_error, 1 + height_error, steps):
        for pf in np.linspace(1 - pitch_error, 1 + pitch_error, steps):
            pitch = min(geometry.pose.pitch_deg * pf, 90.0)
            true_geo = CameraGeometry(
                width=geometry.width,
                height=geometry.height,
                intrinsics=geometry.intrinsics,
                pose=Pose(height_m=geometry.pose.height_m * hf, pitch_deg=pitch),
            )
            _, _, true_delta = true_geo.pixel_size(rows)
            ratio = nominal / true_delta
            worst = max(worst, float(np.nanmax(ratio)))
    return worst
