"""Metric clearance of landing points on synthetic scenes: the true distance in metres to the ground
footprint of the nearest road, car or building (hidden parts included), from the scene's meta file.

The landing point of a candidate is where the ray of its centre pixel meets the ground plane, seen
with the pose the scene was **rendered** with (its meta), not the pose the planner assumed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from assurance.dataio.poses import read_meta
from assurance.dataio.uavid import Sample
from assurance.scenes.world import World, pixel_clearance_m
from el.base.userfiles import UserFileError
from el.geometry.camera import CameraGeometry, Intrinsics, Pose

_CACHE: dict[str, tuple[World, dict]] = {}


def load_meta(path: str | Path) -> dict:
    """A scene's meta JSON; ValueError naming the file when missing or malformed."""
    path = Path(path)
    try:  # read bounded (a FIFO or /dev/zero there is refused, naming it)
        return read_meta(path)
    except FileNotFoundError:
        raise ValueError(f"{path}: no meta file (only synthetic scenes carry a world model)") from None
    except UserFileError:
        raise
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: unreadable meta file: {exc}") from None


def scene_world(meta_path: str | Path) -> tuple[World, dict]:
    """The footprint world model and meta dict of a scene (cached per process)."""
    key = str(meta_path)
    if key not in _CACHE:
        meta = load_meta(meta_path)
        _CACHE.clear()  # one scene at a time: footprints can be large
        _CACHE[key] = (World.from_meta(meta), meta)
    return _CACHE[key]


def render_geometry(meta: dict, size: tuple[int, int]) -> CameraGeometry:
    """The camera the scene was rendered with, for an image of ``size``."""
    return CameraGeometry(width=size[0], height=size[1], pose=Pose(**meta["pose"]),
                          intrinsics=Intrinsics(**meta["intrinsics"]))


def clearance_at(meta_path: str | Path, size: tuple[int, int], xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Clearance (m) of points in continuous image coordinates (x, y) of an image of ``size``."""
    world, meta = scene_world(meta_path)
    geo = render_geometry(meta, size)
    return pixel_clearance_m(world, geo, np.asarray(xs, float) - 0.5, np.asarray(ys, float) - 0.5)


def sample_clearance_m(sample: Sample, size: tuple[int, int], xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Clearance (m) of candidate centres of a UAVid-layout sample that has a meta file."""
    return clearance_at(sample.meta_path(), size, xs, ys)
