"""Synthetic scene generator: determinism, classes, geometry, metric clearance, writer and CLI."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from assurance.dataio.uavid import iter_samples, read_image, read_labels
from assurance.scenes import (
    SPLIT_BASE,
    World,
    default_geometry,
    generate_scene,
    generate_world,
    pixel_clearance_m,
    render,
    scene_seed,
    write_dataset,
)
from assurance.scenes.generate import write_scene
from assurance.scenes.geom import PolygonSet, rect
from assurance.scenes.styles import HELD_OUT_STYLES, STYLES, choose_style
from assurance.scenes.world import Block, Crown, Look, Sun
from el.classes.labels import CLASS_IDS, NUM_CLASSES, PALETTE, UAVID
from el.geometry.camera import CameraGeometry, Pose

SIZE = (480, 270)
BATCH = [(0, "downtown"), (1, "residential"), (2, "park"), (3, "campus"), (4, "industrial"), (5, "downtown")]


@pytest.fixture(scope="module")
def batch():
    return [generate_scene(seed, size=SIZE, style=style) for seed, style in BATCH]


def test_same_seed_same_bytes(tmp_path):
    write_scene(tmp_path / "a", 0, 7, "train", (320, 180))
    write_scene(tmp_path / "b", 0, 7, "train", (320, 180))
    for sub in ("Images", "Labels", "meta"):
        fa = sorted((tmp_path / "a" / "seq00" / sub).iterdir())
        fb = sorted((tmp_path / "b" / "seq00" / sub).iterdir())
        assert [f.read_bytes() for f in fa] == [f.read_bytes() for f in fb]
    a, b = generate_world(7), generate_world(8)
    assert (a.style, a.sun, len(a.blocks)) != (b.style, b.sun, len(b.blocks))


# What an AVX2 machine runs where this one has AVX-512: OpenCV's dispatched kernels, NumPy's and Intel IPP's code paths.
AVX2_LIKE = {"OPENCV_CPU_DISABLE": "AVX512F", "NPY_DISABLE_CPU_FEATURES": "X86_V4", "OPENCV_IPP": "avx2"}


def _has_avx512() -> bool:
    try:
        return " avx512f" in Path("/proc/cpuinfo").read_text()
    except OSError:
        return False


@pytest.mark.skipif(not _has_avx512(), reason="needs a CPU with AVX-512 to run both code paths")
def test_scene_bytes_do_not_depend_on_the_cpus_vector_units(tmp_path):
    """An auditor regenerates a split on another machine and gets the same files (the card's data hashes hold): the
    scenes a process with AVX-512 writes are the bytes one limited to AVX2 writes (NumPy's float32 log1p and power
    differ in their last bits between the two, so the renderer must not lean on them)."""
    def synth(out, env):
        cmd = [sys.executable, "-m", "assurance", "synth", "--out", str(out), "--split", "val", "--scenes", "2",
               "--seed", "3", "--size", "480x270", "-q"]
        subprocess.run(cmd, check=True, env={**os.environ, **env}, capture_output=True, timeout=120)
        return {f.relative_to(out).as_posix(): f.read_bytes() for f in sorted(out.rglob("*.png"))}
    wide, narrow = synth(tmp_path / "wide", {}), synth(tmp_path / "narrow", AVX2_LIKE)
    assert len(wide) == 4 and wide == narrow


def test_every_class_appears_across_a_small_batch(batch):
    seen = set()
    for scene in batch:
        seen |= set(np.unique(scene.labels).tolist())
    assert seen == set(range(NUM_CLASSES))


def test_class_shares_are_plausible(batch):
    forbidden = [CLASS_IDS[n] for n in ("road", "building", "static_car", "moving_car")]
    shares = []
    for scene in batch:
        counts = np.bincount(scene.labels.ravel(), minlength=NUM_CLASSES) / scene.labels.size
        assert math.isclose(sum(scene.meta["class_shares"].values()), 1.0, abs_tol=1e-4)
        assert np.allclose([scene.meta["class_shares"][n] for n in scene.meta["class_shares"]], counts, atol=1e-5)
        shares.append(counts[forbidden].sum())
    assert 0.15 <= float(np.mean(shares)) <= 0.80
    assert all(0.02 <= s <= 0.95 for s in shares)


def test_pixel_ground_pixel_round_trip(batch):
    g = default_geometry(SIZE)
    rng = np.random.default_rng(0)
    cols, rows = rng.uniform(0, SIZE[0] - 1, 500), rng.uniform(0, SIZE[1] - 1, 500)
    x, y = g.pixel_to_ground(cols, rows)
    c2, r2 = g.ground_to_pixel(x, y)
    assert np.allclose(c2, cols, atol=1e-6) and np.allclose(r2, rows, atol=1e-6)


def test_road_pixels_see_road_footprints(batch):
    """Every pixel labelled road looks at the ground inside a road footprint (up to one pixel)."""
    g = default_geometry(SIZE)
    rows, cols = np.mgrid[0:SIZE[1], 0:SIZE[0]]
    _, along, _ = g.pixel_size(rows[:, 0])
    for scene in batch[:3]:
        road = scene.labels == CLASS_IDS["road"]
        x, y = g.pixel_to_ground(cols[road], rows[road])
        d = scene.world.clearance_m(x, y, classes=("road",))
        tol = along[rows[road]] * 1.5
        assert np.mean(d <= tol) > 0.995
        assert np.all(d <= 3 * tol)


def test_clearance_of_a_hand_placed_building():
    world = World(seed=0, style="test", lighting="noon", sun=Sun(0.0, 45.0))
    world.add_block(Block(0.0, 60.0, 10.0, 6.0, 0.0, 0.0, 12.0, CLASS_IDS["building"],
                          Look("roof_membrane", (0.5, 0.5, 0.5)), Look("facade", (0.7, 0.7, 0.7))))
    x = np.array([0.0, 4.9, 8.0, 0.0, 8.0, -5.0])
    y = np.array([60.0, 62.9, 60.0, 50.0, 66.0, 57.0])
    expected = np.array([0.0, 0.0, 3.0, 7.0, math.hypot(3.0, 3.0), 0.0])
    assert np.allclose(world.clearance_m(x, y), expected, atol=1e-9)
    # the same through a camera: pixel -> ground ray -> distance
    g = default_geometry(SIZE)
    col, row = g.ground_to_pixel(np.array([8.0, 0.0]), np.array([60.0, 50.0]))
    assert np.allclose(pixel_clearance_m(world, g, col, row), [3.0, 7.0], atol=1e-6)
    # and from the meta dict alone
    again = World.from_meta(json.loads(json.dumps({"footprints": world.footprints_meta()})))
    assert np.allclose(again.clearance_m(x, y), expected, atol=1e-3)


def test_polygon_distance_matches_brute_force():
    rng = np.random.default_rng(3)
    polys = [rect(*rng.uniform([-50, 0], [50, 100]), *rng.uniform(1, 15, 2), rng.uniform(0, 3)) for _ in range(60)]
    ps = PolygonSet(polys)
    x, y = rng.uniform(-60, 60, 3000), rng.uniform(-10, 110, 3000)
    d = ps.distance(x, y)
    from matplotlib.path import Path as MplPath

    inside = np.zeros(len(x), bool)
    for p in polys:
        inside |= MplPath(p).contains_points(np.c_[x, y])
    seg = np.concatenate([np.c_[p, np.roll(p, -1, axis=0)] for p in polys])
    dx, dy = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
    t = np.clip(((x[:, None] - seg[:, 0]) * dx + (y[:, None] - seg[:, 1]) * dy) / (dx**2 + dy**2), 0, 1)
    brute = np.hypot(x[:, None] - seg[:, 0] - t * dx, y[:, None] - seg[:, 1] - t * dy).min(axis=1)
    brute[inside] = 0
    assert np.allclose(d, brute, atol=1e-9)


def test_tree_over_road_keeps_the_road_footprint():
    world = World(seed=0, style="test", lighting="noon", sun=Sun(30.0, 50.0))
    world.add_region(rect(0, 60, 400, 400, 0), CLASS_IDS["clutter"], Look("soil", (0.4, 0.35, 0.3)), 0)
    world.add_region(rect(0, 50, 200, 8, 0), CLASS_IDS["road"], Look("asphalt", (0.3, 0.3, 0.3)), 8)
    blobs = np.array([[0.0, 50.0, 6.0, 4.0, 3.0]])
    world.add_crown(Crown(blobs, CLASS_IDS["tree"], Look("foliage", (0.2, 0.35, 0.15))))
    g = default_geometry(SIZE)
    out = render(world, g)
    tree = out.labels == CLASS_IDS["tree"]
    assert tree.any() and out.void == 0
    rows, cols = np.nonzero(tree)
    x, y = g.pixel_to_ground(cols, rows)
    under_road = np.abs(y - 50) < 3.5
    assert under_road.any()
    assert np.all(world.clearance_m(x[under_road], y[under_road]) == 0)
    assert len(world.footprints["road"]) == 1


def test_generated_trees_hide_roads_that_stay_forbidden(batch):
    g = default_geometry(SIZE)
    found = 0
    for scene in batch:
        rows, cols = np.nonzero(scene.labels == CLASS_IDS["tree"])
        x, y = g.pixel_to_ground(cols, rows)
        on_road = scene.world.clearance_m(x, y, classes=("road",)) == 0
        found += int(on_road.sum())
        assert np.all(scene.world.clearance_m(x[on_road], y[on_road]) == 0)
    assert found > 0


def test_meta_alone_gives_the_same_clearance(batch):
    scene = batch[0]
    g = default_geometry(SIZE)
    again = World.from_meta(json.loads(json.dumps(scene.meta)))
    rows, cols = np.mgrid[0:SIZE[1]:7, 0:SIZE[0]:7]
    a = pixel_clearance_m(scene.world, g, cols.ravel(), rows.ravel())
    b = pixel_clearance_m(again, g, cols.ravel(), rows.ravel())
    near = a < scene.meta["footprints_margin_m"]
    assert np.allclose(a[near], b[near], atol=2e-3)
    for key in ("version", "seed", "split", "style", "pose", "intrinsics", "image_size", "class_shares", "footprints"):
        assert key in scene.meta


def test_world_does_not_depend_on_the_pose():
    g0 = default_geometry(SIZE)
    world = generate_world(11, geometry=g0)
    for height, pitch in ((60.0, 36.0), (40.0, 54.0)):  # the widest and the narrowest views
        g = CameraGeometry(width=SIZE[0], height=SIZE[1], pose=Pose(height_m=height, pitch_deg=pitch))
        out = render(world, g)
        assert out.void == 0, f"unmodelled pixels at height {height}, pitch {pitch}"
        assert out.labels.shape == (SIZE[1], SIZE[0])


def test_splits_have_disjoint_seeds_and_train_never_sees_held_out_styles():
    assert scene_seed("train", 5) == SPLIT_BASE["train"] + 5
    assert scene_seed("val", 5, seed=3) == SPLIT_BASE["val"] + 8
    with pytest.raises(ValueError):
        scene_seed("bogus", 0)
    rng = np.random.default_rng(0)
    assert all(choose_style(rng, "train").name in STYLES for _ in range(200))
    assert any(choose_style(rng, "test").name in HELD_OUT_STYLES for _ in range(200))


def test_writer_layout_reads_back_and_resumes(tmp_path):
    keys = write_dataset(tmp_path, 2, seed=0, split="val", size=(320, 180), progress=False)
    assert keys == ["seq00/000000", "seq00/000001"]
    samples = list(iter_samples(tmp_path, check_sizes=True))
    assert [s.key for s in samples] == keys
    ids = read_labels(samples[1].label_path, labels=UAVID)
    assert ids.shape == (180, 320) and ids.max() < NUM_CLASSES
    meta = json.loads(samples[1].meta_path().read_text())
    assert meta["seed"] == SPLIT_BASE["val"] + 1 and meta["split"] == "val"
    stamp = samples[0].image_path.stat().st_mtime_ns
    write_dataset(tmp_path, 2, seed=0, split="val", size=(320, 180), progress=False)
    assert samples[0].image_path.stat().st_mtime_ns == stamp


def test_cli_synth_and_preview(tmp_path, monkeypatch, capsys):
    from assurance import cli

    monkeypatch.setattr(cli, "COMMANDS", {"synth": "synth", "preview": "preview"})
    out = tmp_path / "data"
    assert cli.main(["synth", "--out", str(out), "--scenes", "1", "--size", "256x144", "--no-progress"]) == 0
    assert len(list(iter_samples(out))) == 1
    png = tmp_path / "preview.png"
    assert cli.main(["preview", "--data", str(out), "--index", "0", "--out", str(png), "--width", "200"]) == 0
    sheet = read_image(png)
    assert sheet.shape[1] == 406 and (sheet == PALETTE[CLASS_IDS["road"]]).all(axis=2).any()
    capsys.readouterr()
    assert cli.main(["synth", "--out", str(out), "--scenes", "1", "--size", "big"]) == 2
    assert "--size must look like WIDTHxHEIGHT" in capsys.readouterr().err
    assert cli.main(["preview", "--data", str(out), "--index", "5", "--out", str(png)]) == 2
    assert "out of range" in capsys.readouterr().err
