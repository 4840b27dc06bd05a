"""Scene generation: seeded worlds, rendered scenes with meta, and UAVid-layout datasets on disk.

Splits use disjoint seed ranges (``SPLIT_BASE``): scene ``i`` of a split with offset ``seed``
has seed ``SPLIT_BASE[split] + seed + i``. The same seed always gives the same PNG bytes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from assurance.dataio.poses import POSES_FILE, read_meta, write_poses
from assurance.dataio.uavid import sample_paths, write_image
from assurance.files import atomic_write_bytes
from assurance.progress import progress
from assurance.scenes.builder import Builder
from assurance.scenes.layout import build_city
from assurance.scenes.rand import Rand
from assurance.scenes.renderer import render
from assurance.scenes.styles import ALL_STYLES, HELD_OUT_STYLES, LIGHTINGS, Style, choose_style, get_style
from assurance.scenes.view import coverage_domain, visible_ground
from assurance.scenes.world import Sun, World
from assurance.workers import die_with_parent
from el.classes.labels import CLASS_NAMES, NUM_CLASSES, PALETTE
from el.geometry.camera import HEIGHT_M, PITCH_DEG, CameraGeometry, Intrinsics, Pose, check_geometry

GENERATOR_VERSION = "1.1"  # 1.1: look-alike hazards (tracks, shared streets, low sheds, stray and verge cars)
SPLIT_BASE: dict[str, int] = {"train": 0, "val": 1_000_000, "test": 2_000_000}
FRAMES_PER_SEQUENCE = 100
FOOTPRINT_MARGIN_M = 25.0
DEFAULT_SIZE = (3840, 2160)


@dataclass
class Scene:
    """A generated scene: RGB image (H, W, 3) uint8, class ids (H, W) uint8, meta dict and its world."""

    image: np.ndarray
    labels: np.ndarray
    meta: dict[str, Any]
    world: World


def scene_seed(split: str, index: int, seed: int = 0) -> int:
    """Seed of scene ``index`` of a split (disjoint ranges per split)."""
    if split not in SPLIT_BASE:
        raise ValueError(f"split must be one of {', '.join(SPLIT_BASE)}, got {split!r}")
    if not 0 <= seed + index < 1_000_000:
        raise ValueError(f"seed + index must lie in [0, 1000000), got {seed + index}")
    return SPLIT_BASE[split] + seed + index


def split_of_seed(seed: int) -> str:
    """The split a scene seed belongs to."""
    for name, base in sorted(SPLIT_BASE.items(), key=lambda kv: -kv[1]):
        if seed >= base:
            return name
    return "train"


def default_geometry(size: tuple[int, int] = DEFAULT_SIZE, pose: Pose | None = None,
                     intrinsics: Intrinsics | None = None) -> CameraGeometry:
    """Camera of a scene: Phantom 4 at 50 m and 45 degrees unless told otherwise."""
    return CameraGeometry(width=int(size[0]), height=int(size[1]), intrinsics=intrinsics or Intrinsics(),
                          pose=pose or Pose())


def generate_world(seed: int, *, style: str | Style | None = None, split: str | None = None,
                   geometry: CameraGeometry | None = None) -> World:
    """A seeded world covering every view of ``geometry`` with height and pitch within +-20%."""
    geometry = geometry or default_geometry()
    rng = np.random.default_rng([seed, 7031])
    split = split or split_of_seed(seed)
    st = choose_style(rng, split) if style is None else (get_style(style) if isinstance(style, str) else style)
    lights = [name for name in st.lightings if split != "train" or st.name in HELD_OUT_STYLES or name != "golden"]
    lighting = LIGHTINGS[lights[int(rng.integers(len(lights)))]]
    sun = Sun(float(rng.uniform(0, 360)), float(rng.uniform(*lighting.elevation_deg)))
    world = World(seed=seed, style=st.name, lighting=lighting.name, sun=sun)
    world.grade = _grade(rng, lighting)
    domain = coverage_domain(geometry)
    world.domain = domain
    build_city(Builder(world, Rand(int(rng.integers(2**62))), st, domain))
    return world


def _grade(rng: np.random.Generator, lighting: Any) -> dict[str, Any]:
    """Per-scene camera response: exposure, white balance, contrast, saturation, haze, blur, noise."""
    return {
        "exposure": float(rng.uniform(*lighting.exposure)),
        "white_balance": tuple(float(x) for x in 1 + rng.uniform(-0.05, 0.05, 3)),
        "contrast": float(rng.uniform(0.88, 1.15)),
        "saturation": float(rng.uniform(0.75, 1.1)),
        "gamma": float(rng.uniform(0.9, 1.1)),
        "haze": float(lighting.haze * rng.uniform(0.5, 1.6)),
        "haze_rgb": tuple(float(x) for x in np.array([0.72, 0.75, 0.80]) + rng.uniform(-0.04, 0.04, 3)),
        "blur_px": float(rng.uniform(0.45, 0.85)),
        "sensor_noise": float(rng.uniform(0.006, 0.02)),
        "vignette": float(rng.uniform(0.03, 0.25)),
    }


def scene_meta(world: World, geometry: CameraGeometry, labels: np.ndarray, split: str | None) -> dict[str, Any]:
    """The meta record of a rendered scene (JSON-ready)."""
    counts = np.bincount(labels.ravel(), minlength=NUM_CLASSES).astype(np.float64)
    shares = {name: round(float(c / labels.size), 6) for name, c in zip(CLASS_NAMES, counts, strict=True)}
    vis = visible_ground(geometry)
    m = FOOTPRINT_MARGIN_M
    region = (float(vis[:, 0].min() - m), float(vis[:, 0].max() + m), float(vis[:, 1].min() - m),
              float(vis[:, 1].max() + m))
    return {
        "generator": "assurance.scenes",
        "version": GENERATOR_VERSION,
        "seed": int(world.seed),
        "split": split or split_of_seed(world.seed),
        "style": world.style,
        "held_out_style": world.style in HELD_OUT_STYLES,
        "lighting": world.lighting,
        "sun": {"azimuth_deg": round(world.sun.azimuth_deg, 3), "elevation_deg": round(world.sun.elevation_deg, 3)},
        "pose": {"height_m": geometry.pose.height_m, "pitch_deg": geometry.pose.pitch_deg},
        "intrinsics": geometry.intrinsics.to_dict(),
        "image_size": [geometry.width, geometry.height],
        "class_shares": shares,
        "footprints_region": [round(x, 3) for x in region],
        "footprints_margin_m": m,
        "footprints": world.footprints_meta(region),
    }


def generate_scene(seed: int, *, size: tuple[int, int] = DEFAULT_SIZE, pose: Pose | None = None,
                   style: str | None = None, split: str | None = None, intrinsics: Intrinsics | None = None) -> Scene:
    """Generate and render one scene. The world covers poses within +-20% of ``pose``."""
    if style is not None and style not in ALL_STYLES:
        raise ValueError(f"unknown style {style!r}; known: {', '.join(ALL_STYLES)}")
    geometry = default_geometry(size, pose, intrinsics)
    world = generate_world(seed, style=style, split=split, geometry=geometry)
    out = render(world, geometry)
    return Scene(out.image, out.labels, scene_meta(world, geometry, out.labels, split), world)


def _check_rendered(root: Path, index: int, view: ViewPlan | None, seed: int) -> bool:
    """False for a complete scene rendered as ``view`` asks (None: not checked); ValueError when it was not."""
    if view is None:
        return False
    meta_path = sample_paths(root, *frame_location(index))[2]
    meta = read_meta(meta_path)
    pose = view.pose_for(seed)
    want = {"pose": {"height_m": pose.height_m, "pitch_deg": pose.pitch_deg}, "intrinsics": view.intrinsics.to_dict()}
    for key, value in want.items():
        if meta.get(key) != value:
            raise ValueError(f"{meta_path}: scene rendered with {key} {meta.get(key)}, not {value}; "
                             "use another --out folder")
    return False


def _write_sidecars(root: Path, n: int, seed: int, split: str, view: ViewPlan) -> None:
    """Each sequence's ``poses.csv``: the pose every scene of it is (or will be) rendered at."""
    by_seq: dict[str, dict[str, Pose]] = {}
    for i in range(n):
        seq, frame = frame_location(i)
        by_seq.setdefault(seq, {})[frame] = view.pose_for(scene_seed(split, i, seed))
    for seq, poses in by_seq.items():
        write_poses(root / seq / POSES_FILE, poses)


# -- datasets on disk ---------------------------------------------------------------------------
def frame_location(index: int) -> tuple[str, str]:
    """(sequence, frame) names of dataset item ``index``: seq00/000000 ... 100 frames per sequence."""
    return f"seq{index // FRAMES_PER_SEQUENCE:02d}", f"{index % FRAMES_PER_SEQUENCE:06d}"


def scene_complete(root: str | Path, index: int) -> bool:
    """Whether image, labels and meta of item ``index`` all exist (the meta is written last)."""
    seq, frame = frame_location(index)
    return all(p.is_file() and p.stat().st_size > 0 for p in sample_paths(root, seq, frame))


@dataclass(frozen=True)
class ViewPlan:
    """The camera scenes are rendered with: intrinsics, a nominal pose, and optional per-scene ranges of
    height and pitch from which each scene draws its pose, seeded by the scene seed (deterministic)."""

    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    pose: Pose = field(default_factory=Pose)
    heights: tuple[float, float] | None = None
    pitches: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        for name, rng, (lo, hi) in (("heights", self.heights, HEIGHT_M), ("pitches", self.pitches, PITCH_DEG)):
            if rng is not None and not (len(rng) == 2 and lo <= rng[0] <= rng[1] <= hi):
                raise ValueError(f"{name} must be a range LOW:HIGH with {lo:g} <= LOW <= HIGH <= {hi:g}, got {rng!r}")

    @property
    def is_default(self) -> bool:
        """Whether scenes render as they always did (Phantom 4, 50 m, 45 degrees, one pose)."""
        return self == ViewPlan()

    def pose_for(self, seed: int) -> Pose:
        """The pose of scene ``seed``: drawn from the ranges (to 0.01), else the nominal pose."""
        if self.heights is None and self.pitches is None:
            return self.pose
        rng = np.random.default_rng([seed, 5309])
        height = round(float(rng.uniform(*self.heights)), 2) if self.heights else self.pose.height_m
        pitch = round(float(rng.uniform(*self.pitches)), 2) if self.pitches else self.pose.pitch_deg
        return Pose(height_m=height, pitch_deg=pitch)

    def check(self, size: tuple[int, int]) -> None:
        """ValueError when a pose of the plan is one the generator or the planner cannot handle at ``size``."""
        hs = self.heights or (self.pose.height_m,) * 2
        ps = self.pitches or (self.pose.pitch_deg,) * 2
        for h in hs:
            for p in ps:
                g = default_geometry(size, Pose(height_m=h, pitch_deg=p), self.intrinsics)
                check_geometry(g)
                coverage_domain(g)  # the whole view must see the ground (the generator models the ground only)


def write_scene(root: str | Path, index: int, seed: int, split: str, size: tuple[int, int],
                compression: int = 1, view: ViewPlan | None = None) -> str:
    """Generate scene ``seed`` and write it as item ``index`` (image, labels, then meta); returns its key."""
    seq, frame = frame_location(index)
    img_path, lab_path, meta_path = sample_paths(root, seq, frame)
    if view is None or view.is_default:
        scene = generate_scene(seed, size=size, split=split)
    else:
        scene = generate_scene(seed, size=size, split=split, pose=view.pose_for(seed), intrinsics=view.intrinsics)
    write_image(img_path, scene.image, compression=compression)
    atomic_write_bytes(lab_path, encode_labels(scene.labels))
    atomic_write_bytes(meta_path, (json.dumps(scene.meta, separators=(",", ":")) + "\n").encode())
    return f"{seq}/{frame}"


def encode_labels(ids: np.ndarray) -> bytes:
    """Class ids (H, W) as a colour-coded UAVid label PNG (RGB), run-length encoded: fast and small."""
    lut = np.zeros((256, 3), np.uint8)
    lut[: len(PALETTE)] = PALETTE
    bgr = cv2.merge([cv2.LUT(ids, lut[:, c].copy()) for c in (2, 1, 0)])
    ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 1,
                                         cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE])
    if not ok:
        raise RuntimeError("could not encode the label PNG")
    return buf.tobytes()


def _write_job(args: tuple[str, int, int, str, tuple[int, int], ViewPlan | None]) -> str:
    root, index, seed, split, size, view = args
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import cv2

    cv2.setNumThreads(1)
    return write_scene(root, index, seed, split, size, view=view)


def _iterate(items: Iterator[str], total: int, desc: str, enabled: bool) -> Iterator[str]:
    """Progress on stderr when enabled: a bar on a terminal, plain lines otherwise (``assurance.progress``)."""
    yield from progress(items, total=total, desc=desc, enabled=enabled)


def write_dataset(out: str | Path, n: int, seed: int = 0, split: str = "train",
                  size: tuple[int, int] = DEFAULT_SIZE, *, progress: bool = True, jobs: int = 1,
                  view: ViewPlan | None = None) -> list[str]:
    """Write ``n`` scenes of ``split`` under ``out`` in the UAVid layout; complete ones are skipped.

    ``view``: camera and poses (default: Phantom 4 at 50 m, 45 degrees, no sidecar). Another view also
    writes each sequence's ``poses.csv``; a complete scene rendered with another camera or pose is an error.
    Returns the keys (``seqNN/NNNNNN``) of the scenes written or found complete.
    """
    if n < 0:
        raise ValueError(f"number of scenes must be >= 0, got {n}")
    out = Path(out)
    view = None if view is None or view.is_default else view
    if view is not None:
        view.check(tuple(size))
    todo = [(str(out), i, scene_seed(split, i, seed), split, tuple(size), view) for i in range(n)
            if not scene_complete(out, i) or _check_rendered(out, i, view, scene_seed(split, i, seed))]
    keys = ["/".join(frame_location(i)) for i in range(n)]
    _render_all(todo, split, progress, jobs)
    if view is not None:  # after the scenes: a sidecar names only frames that have an image
        _write_sidecars(out, n, seed, split, view)
    return keys


def _render_all(todo: list[Any], split: str, progress: bool, jobs: int) -> None:
    """Render and write the scenes of ``todo`` (``_write_job`` arguments), in worker processes when jobs > 1."""
    if not todo:
        return
    if jobs <= 1:
        results: Iterator[str] = (_write_job(t) for t in todo)
        for _ in _iterate(results, total=len(todo), desc=f"synth {split}", enabled=progress):
            pass
    else:
        with ProcessPoolExecutor(max_workers=jobs, initializer=die_with_parent, initargs=(os.getpid(),)) as pool:
            for _ in _iterate(pool.map(_write_job, todo), total=len(todo), desc=f"synth {split}", enabled=progress):
                pass
