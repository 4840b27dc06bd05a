"""Look-alike hazards: each adds a forbidden thing that resembles the ground around it, with its footprint."""

from __future__ import annotations

import numpy as np
import pytest

from assurance.scenes import default_geometry, generate_world, render
from assurance.scenes.builder import Builder
from assurance.scenes.lookalikes import low_building, shared_street, stray_cars, track
from assurance.scenes.rand import Rand
from assurance.scenes.styles import STYLES
from assurance.scenes.view import coverage_domain
from assurance.scenes.world import Look, Sun, World
from el.classes.labels import CLASS_IDS

SIZE = (480, 270)
GROUND_MATERIALS = {"roof_green", "roof_gravel", "roof_concrete", "grass"}


def _builder(seed: int = 3) -> Builder:
    world = World(seed=seed, style="park", lighting="noon", sun=Sun(30.0, 50.0))
    domain = coverage_domain(default_geometry(SIZE))
    world.domain = domain
    return Builder(world, Rand(seed), STYLES["park"], domain)


def test_track_is_a_gravel_or_dirt_road_with_a_footprint():
    b = _builder()
    track(b, 0, 60, 0, 40)
    roads = [r for r in b.world.regions if r.label == CLASS_IDS["road"]]
    assert roads and {r.look.material for r in roads} <= {"gravel", "soil"}
    assert len(b.world.footprints["road"]) == 1  # the ruts add no second footprint
    x, y = b.world.footprints["road"][0].mean(axis=0)
    assert b.world.clearance_m(x, y) == 0
    assert not b.free_world(float(x), float(y), 0.5)  # later objects keep off the track


def test_shared_street_is_paved_like_its_square():
    b = _builder()
    ground = Look("pavers", (0.55, 0.54, 0.52), cell=(0.5, 0.3, 0.44, 0.42))
    shared_street(b, 0, 50, 0, 50, ground)
    road = next(r for r in b.world.regions if r.label == CLASS_IDS["road"])
    assert road.look.material == "pavers" and road.look.cell == (0.3, 0.5, 0.42, 0.44)  # laid crosswise
    assert np.allclose(road.look.rgb, ground.rgb, atol=0.06) and not np.allclose(road.look.rgb, ground.rgb, atol=0.01)
    assert b.world.footprints["road"]


def test_low_building_is_low_and_roofed_like_the_ground():
    b = _builder()
    for _ in range(10):
        low_building(b, 0, 40, 0, 40)
    sheds = [blk for blk in b.world.blocks if blk.label == CLASS_IDS["building"]]
    assert sheds, "no shed placed on an empty 40 m square"
    assert all(blk.h <= 4.0 for blk in sheds)
    assert {blk.top.material for blk in sheds} <= GROUND_MATERIALS
    assert len(b.world.footprints["building"]) == len(sheds)


def test_stray_cars_stand_inside_the_block_as_static_cars():
    b = _builder()
    stray_cars(b, 0, 40, 0, 40, 4)
    cars = b.world.footprints["static_car"]
    assert 1 <= len(cars) <= 4
    for fp in cars:
        a, c = b.to_local(*fp.mean(axis=0))
        assert 0 < a < 40 and 0 < c < 40


@pytest.mark.parametrize("style", ["park", "industrial"])
def test_generated_cities_carry_lookalikes_labelled_forbidden(style):
    """Across a few worlds of a style, tracks (road on gravel/soil) and low sheds do appear and render."""
    tracks = sheds = 0
    for seed in range(4):
        world = generate_world(seed, style=style)
        tracks += sum(r.label == CLASS_IDS["road"] and r.look.material in ("gravel", "soil") for r in world.regions)
        sheds += sum(blk.label == CLASS_IDS["building"] and blk.top.material in GROUND_MATERIALS and blk.h <= 4
                     for blk in world.blocks)
    assert tracks > 0 and sheds > 0
    out = render(world, default_geometry(SIZE))
    assert out.void == 0
