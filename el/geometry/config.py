"""Configuration of the core model (CM): valid pixels, regions, representatives, ranking (docs/architecture.md 2-3).

One frozen keyword-only dataclass, validated when it is built: a bad value raises a ValueError
that names the parameter, the value and the allowed range, before any image is processed.
``to_dict()`` is what a decision records under ``"config"``; ``from_dict()`` reads it back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

from el.geometry.camera import (
    CAMERAS,
    FOV_SENSOR_WIDTH_MM,
    REACH_BOUNDS_M,
    REACH_M,
    CameraGeometry,
    Intrinsics,
    Pose,
    SafetyParams,
)

SEED_LIMIT = 2**32
"""Seeds lie in [0, 2^32): every generator a seed reaches (numpy, torch, MC dropout's ``seed + k``) takes them."""
MODES = ("exact", "paper")
REGION_METHODS = ("fast", "dbscan")


def check_seed(value: Any, name: str = "seed") -> int:
    """A valid seed: an integer in [0, 2^32), else ValueError naming ``name``, the value and the range."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < SEED_LIMIT:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r} (seeds lie in [0, 2^32), below {SEED_LIMIT})")
    return value


@dataclass(frozen=True, kw_only=True)
class CoreConfig:
    """Parameters of the CM post-processing, with the paper's defaults.

    Parameters
    ----------
    mode : {"exact", "paper"}
        "exact": one Euclidean distance transform compared row by row with R_px(i) (a disc).
        "paper": 10 stripes, one radius per stripe (its centre row), a square of half-width R_px.
    n_star : int
        Target number of representatives N* (each region gets at least one).
    dbscan_eps : float
        DBSCAN neighbourhood radius in working pixels (>= 1).
    dbscan_min_samples : int
        DBSCAN core-point threshold (the point itself included).
    region_method : {"fast", "dbscan"}
        "fast": density mask + connected components (same partition of core points as DBSCAN);
        "dbscan": scikit-learn's DBSCAN, the reference (seconds on 10^5 pixels).
    kmeans_max_points : int
        K-means runs on a regular subsample of a region larger than this.
    kmeans_seed : int
        Seed of K-means (k-means++ initialisation).
    kmeans_n_init : int
        Number of K-means initialisations (best inertia kept).
    overlap_max : float
        A candidate whose disc overlaps an already kept one by more than this share of its area is dropped.
    alpha : float
        Weight of the semantic hazard: H = alpha H_s + (1 - alpha) H_d.
    d_max_factor : float
        d_max = d_max_factor * R_px: beyond it the distance hazard is 0.
    working_width : int
        Width of the working (low) resolution; the height keeps the aspect ratio.
    safety : SafetyParams
        Safety radius R (m) and coefficient beta.
    pose : Pose
        Camera height (m) and pitch (degrees below the horizon).
    intrinsics : Intrinsics
        Sensor width and focal length (mm).
    reach_m : float
        How far ahead of the nadir point (m) the UAV can still land: a leading stripe whose top row sees the
        ground farther is unreachable (``CameraGeometry.unreachable_stripes``). The default 90 m lies between the
        83.9 m and 100.9 m the top rows of stripes 2 and 1 see in the paper's case (Phantom 4, 50 m, 45 degrees),
        so that case drops exactly the paper's top 2 of 10 stripes; a nadir camera at 5-30 m drops none.
    """

    mode: str = "exact"
    n_star: int = 20
    dbscan_eps: float = 3.0
    dbscan_min_samples: int = 5
    region_method: str = "fast"
    kmeans_max_points: int = 500
    kmeans_seed: int = 0
    kmeans_n_init: int = 1
    overlap_max: float = 0.25
    alpha: float = 0.5
    d_max_factor: float = 3.0
    working_width: int = 1024
    safety: SafetyParams = field(default_factory=SafetyParams)
    pose: Pose = field(default_factory=Pose)
    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    reach_m: float = REACH_M

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.region_method not in REGION_METHODS:
            raise ValueError(f"region_method must be one of {REGION_METHODS}, got {self.region_method!r}")
        _int_in("n_star", self.n_star, 1, 1000)
        _int_in("dbscan_min_samples", self.dbscan_min_samples, 1, 1000)
        _int_in("kmeans_max_points", self.kmeans_max_points, 10, 10_000_000)
        _int_in("kmeans_seed", self.kmeans_seed, 0, 2**32 - 1)
        _int_in("kmeans_n_init", self.kmeans_n_init, 1, 100)
        _int_in("working_width", self.working_width, 16, 8192)
        _float_in("dbscan_eps", self.dbscan_eps, 1.0, 50.0)
        _float_in("overlap_max", self.overlap_max, 0.0, 1.0)
        _float_in("alpha", self.alpha, 0.0, 1.0)
        _float_in("d_max_factor", self.d_max_factor, 1.0 + 1e-9, 10.0)
        _float_in("reach_m", self.reach_m, *REACH_BOUNDS_M)
        for name, cls in (("safety", SafetyParams), ("pose", Pose), ("intrinsics", Intrinsics)):
            if not isinstance(getattr(self, name), cls):
                raise ValueError(f"{name} must be a {cls.__name__}, got {type(getattr(self, name)).__name__}")

    def geometry(self, width: int, height: int) -> CameraGeometry:
        """The camera model of this configuration for an image of ``width x height`` pixels."""
        return CameraGeometry(width=width, height=height, intrinsics=self.intrinsics, pose=self.pose,
                              reach_m=self.reach_m)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (the decision's ``"config"``); nested records become dicts."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "intrinsics":
                value = value.to_dict()  # sensor_height_mm only when set: the default records as before
            elif f.name in ("safety", "pose"):
                value = {g.name: getattr(value, g.name) for g in fields(value)}
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CoreConfig:
        """Inverse of ``to_dict``; unknown keys are an error (a typo must not pass silently)."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown CoreConfig keys: {', '.join(unknown)}")
        kwargs = dict(data)
        if isinstance(kwargs.get("safety"), dict):
            kwargs["safety"] = SafetyParams(**kwargs["safety"])
        if isinstance(kwargs.get("pose"), dict):
            kwargs["pose"] = Pose(**kwargs["pose"])
        if isinstance(kwargs.get("intrinsics"), dict):
            kwargs["intrinsics"] = Intrinsics(**kwargs["intrinsics"])
        return cls(**kwargs)


def camera_intrinsics(name: str) -> Intrinsics:
    """The intrinsics of a named camera ("phantom4", "phantom3pro"); ValueError for an unknown name."""
    try:
        return CAMERAS[name]
    except KeyError:
        raise ValueError(f"unknown camera {name!r}; known: {', '.join(sorted(CAMERAS))}") from None


def make_intrinsics(
    camera: str | None = None,
    *,
    sensor_width_mm: float | None = None,
    sensor_height_mm: float | None = None,
    focal_mm: float | None = None,
    hfov_deg: float | None = None,
    name: str | None = None,
) -> Intrinsics:
    """The intrinsics a camera sheet gives: a named preset, or a sensor with a focal length OR a field of view.

    With a preset (``camera``), the other values override its own; without, ``focal_mm`` or ``hfov_deg``
    is required (not both) and the sensor width is ``sensor_width_mm`` (for a field of view alone: the
    35 mm-equivalent 36 mm). ValueError names the field, the value and the allowed range.
    """
    if focal_mm is not None and hfov_deg is not None:
        raise ValueError(f"give focal_mm ({focal_mm!r}) or hfov_deg ({hfov_deg!r}), not both")
    base = camera_intrinsics(camera) if camera is not None else None
    if base is None and focal_mm is None and hfov_deg is None:
        if sensor_width_mm is None and sensor_height_mm is None:
            return Intrinsics()
        raise ValueError("a custom sensor needs focal_mm or hfov_deg")
    sw = sensor_width_mm if sensor_width_mm is not None else (base.sensor_width_mm if base else None)
    sh = sensor_height_mm if sensor_height_mm is not None else (base.sensor_height_mm if base else None)
    label = name or (base.name if base and sensor_width_mm is None and focal_mm is None and hfov_deg is None
                     and sensor_height_mm is None else "custom")
    if hfov_deg is not None:
        return Intrinsics.from_fov(hfov_deg, sensor_width_mm=sw if sw is not None else FOV_SENSOR_WIDTH_MM,
                                   sensor_height_mm=sh, name=label)
    if sw is None:
        raise ValueError("a focal length needs sensor_width_mm")
    return Intrinsics(sensor_width_mm=sw, focal_mm=focal_mm if focal_mm is not None else base.focal_mm,  # type: ignore[union-attr]
                      sensor_height_mm=sh, name=label)


def _int_in(name: str, value: object, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")


def _float_in(name: str, value: object, lo: float, hi: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number in [{lo}, {hi}], got {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"{name} must lie in [{lo}, {hi}], got {value!r}")
