"""Look-alike hazards: forbidden things that resemble the open ground around them.

Gravel and dirt access tracks (road), shared-space streets paved like the square they cross
(road), low sheds and garages whose green, gravel or concrete roofs read as lawn or yard
(building), and cars parked on grass, gravel and verges (static car). They put forbidden pixels
where open ground is expected, so the CNN makes the errors the monitors exist to catch (docs/architecture.md
section 5.2: a sizeable share of the core model's candidates must be truly unsafe).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from assurance.scenes import props
from assurance.scenes.builder import L_LOT_PAINT, Builder
from assurance.scenes.materials import MATERIALS
from assurance.scenes.styles import pick
from assurance.scenes.world import Look
from el.classes.labels import CLASS_IDS

ROAD = CLASS_IDS["road"]
L_TRACK = L_LOT_PAINT  # over paths, patches and planters


@dataclass(frozen=True)
class LookalikeMix:
    """How often each block type gets each look-alike hazard (probabilities per block)."""

    track: float = 0.0
    shared_street: float = 0.0
    low_buildings: float = 0.0
    stray_cars: float = 0.0
    max_low_buildings: int = 2
    max_stray_cars: int = 4


MIXES: dict[str, LookalikeMix] = {
    "park": LookalikeMix(track=0.6, low_buildings=0.7, stray_cars=0.5, max_low_buildings=3),
    "lawn": LookalikeMix(track=0.6, low_buildings=0.7, stray_cars=0.6, max_low_buildings=3),
    "vacant": LookalikeMix(track=0.8, low_buildings=0.5, stray_cars=0.7, max_stray_cars=6),
    "sports": LookalikeMix(low_buildings=0.6, stray_cars=0.4),
    "plaza": LookalikeMix(shared_street=0.8, low_buildings=0.4, stray_cars=0.3, max_stray_cars=2),
    "towers": LookalikeMix(shared_street=0.6, stray_cars=0.3, max_stray_cars=2),
    "industrial": LookalikeMix(track=0.6, low_buildings=0.5, stray_cars=0.4),
    "perimeter": LookalikeMix(shared_street=0.4, low_buildings=0.4, stray_cars=0.3, max_low_buildings=2,
                              max_stray_cars=2),
}


def add_ground_lookalikes(b: Builder, kind: str, a0: float, a1: float, b0: float, b1: float,
                          ground: Look | None = None) -> None:
    """Tracks and shared streets of block type ``kind``, laid right after the block's ground so that
    later objects keep off them (trees may still overhang)."""
    mix = MIXES.get(kind)
    if mix is None or min(a1 - a0, b1 - b0) <= 20:
        return
    rng = b.rng
    if mix.track and rng.random() < mix.track:
        track(b, a0, a1, b0, b1)
    if mix.shared_street and rng.random() < mix.shared_street:
        shared_street(b, a0, a1, b0, b1, ground)


def add_object_lookalikes(b: Builder, kind: str, a0: float, a1: float, b0: float, b1: float) -> None:
    """Low look-alike buildings and stray cars of block type ``kind``, placed on free ground."""
    mix = MIXES.get(kind)
    if mix is None:
        return
    rng = b.rng
    if mix.low_buildings and rng.random() < mix.low_buildings:
        for _ in range(int(rng.integers(1, mix.max_low_buildings + 1))):
            low_building(b, a0, a1, b0, b1)
    if mix.stray_cars and rng.random() < mix.stray_cars:
        stray_cars(b, a0, a1, b0, b1, int(rng.integers(1, mix.max_stray_cars + 1)))


def track(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """A gravel or dirt access track (road) across the block, sometimes with darker wheel ruts."""
    rng, pal = b.rng, b.palette
    width = float(rng.uniform(3.0, 4.5))
    material = str(rng.choice(["gravel", "soil"], p=[0.6, 0.4]))
    look = Look(material, pick(rng, pal.gravel if material == "gravel" else pal.soil, 0.1))
    ra0, ra1, rb0, rb1 = b.strip_across(a0, a1, b0, b1, width)
    b.world.add_region(b.rect(ra0, ra1, rb0, rb1), ROAD, look, L_TRACK)
    if rng.random() < 0.5:  # two wheel ruts 1.6 m apart, a shade darker (still road)
        rut = Look(material, tuple(c * 0.85 for c in look.rgb))  # type: ignore[arg-type]
        if ra1 - ra0 > rb1 - rb0:
            mid = (rb0 + rb1) / 2
            ruts = [b.rect(ra0, ra1, mid + o - 0.2, mid + o + 0.2) for o in (-0.8, 0.8)]
        else:
            mid = (ra0 + ra1) / 2
            ruts = [b.rect(mid + o - 0.2, mid + o + 0.2, rb0, rb1) for o in (-0.8, 0.8)]
        b.world.add_region(ruts, ROAD, rut, L_TRACK, footprint=False)
    b.occupy_local(ra0, ra1, rb0, rb1)


def shared_street(b: Builder, a0: float, a1: float, b0: float, b1: float, ground: Look | None) -> None:
    """A shared-space street (road) paved like the square it crosses, sometimes lined with bollards."""
    rng = b.rng
    width = float(rng.uniform(4.0, 6.0))
    base = ground if ground is not None else Look("pavers", pick(rng, b.palette.paving, 0.1))
    # a faint cue, as on real shared streets: a tone a few percent off and the paving laid crosswise
    tone = (1.0 + float(rng.uniform(0.04, 0.09)) * float(rng.choice([-1.0, 1.0])))
    rgb = tuple(min(0.98, c * tone) for c in base.rgb)
    cell = base.cell or MATERIALS[base.material].cell
    if cell is not None:
        cell = (cell[1], cell[0], cell[3], cell[2])
    look = replace(base, rgb=rgb, cell=cell)
    ra0, ra1, rb0, rb1 = b.strip_across(a0, a1, b0, b1, width)
    b.world.add_region(b.rect(ra0, ra1, rb0, rb1), ROAD, look, L_TRACK)
    b.occupy_local(ra0, ra1, rb0, rb1)
    if rng.random() < 0.5:
        step = float(rng.uniform(3.0, 6.0))
        if ra1 - ra0 > rb1 - rb0:
            spots = [(a, c) for a in np.arange(ra0 + 1, ra1 - 1, step) for c in (rb0 - 0.4, rb1 + 0.4)]
        else:
            spots = [(a, c) for c in np.arange(rb0 + 1, rb1 - 1, step) for a in (ra0 - 0.4, ra1 + 0.4)]
        for a, c in spots:
            x, y = b.to_world(float(a), float(c))
            props.add_clutter(b, x, y, b.phi, "bollard")


def low_building(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """A shed, garage or pavilion (building) with a roof like the ground: green, gravel or concrete."""
    rng, pal = b.rng, b.palette
    w, l = float(rng.uniform(3.0, 9.0)), float(rng.uniform(3.0, 7.0))
    if a1 - a0 < w + 4 or b1 - b0 < l + 4:
        return
    for _ in range(6):
        ca, cb = float(rng.uniform(a0 + 2 + w / 2, a1 - 2 - w / 2)), float(rng.uniform(b0 + 2 + l / 2, b1 - 2 - l / 2))
        if b.free_rect_local(ca - w / 2 - 1, ca + w / 2 + 1, cb - l / 2 - 1, cb + l / 2 + 1):
            break
    else:
        return
    kind = str(rng.choice(["roof_green", "roof_gravel", "roof_concrete", "grass"], p=[0.3, 0.3, 0.2, 0.2]))
    colours = {"roof_green": pal.grass + pal.green_roof, "roof_gravel": pal.gravel, "roof_concrete": pal.paving,
               "grass": pal.grass}[kind]
    x, y = b.to_world(ca, cb)
    props.add_building(b, x, y, w, l, b.phi + float(rng.choice([0.0, math.pi / 2])), float(rng.uniform(2.4, 4.0)),
                       style=props.BuildingStyle(roof=Look(kind, pick(rng, colours, 0.1)), parapet=False,
                                                 equipment=False))


def stray_cars(b: Builder, a0: float, a1: float, b0: float, b1: float, n: int) -> None:
    """Static cars left on the lawn, gravel or paving at random headings (no bays, no lines)."""
    rng = b.rng
    for _ in range(n):
        a, c = float(rng.uniform(a0 + 3, a1 - 3)), float(rng.uniform(b0 + 3, b1 - 3))
        if not b.free_local(a, c, 3.0):
            continue
        x, y = b.to_world(a, c)
        props.add_car(b, x, y, float(rng.uniform(0, 2 * math.pi)), moving=False,
                      kind=str(rng.choice(["sedan", "hatch", "suv", "van"], p=[0.4, 0.3, 0.2, 0.1])))
