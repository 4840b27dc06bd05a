"""Block fillers: what stands between the streets (perimeter blocks, towers, houses, parks, plazas...).

Each filler gets the builder and the block's local rectangle [a0, a1] x [b0, b1] (metres, in the
rotated street frame) and adds ground regions and objects inside it.
The detached-house filler lives in :mod:`assurance.scenes.houses`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from assurance.scenes import props
from assurance.scenes.builder import L_DETAIL, L_DETAIL2, L_LOT_PAINT, Builder
from assurance.scenes.geom import ellipse
from assurance.scenes.ground import (
    blob_region,
    ground_region,
    lawn_look,
    park_cars_rows,
    paved_look,
    scatter_bushes,
    scatter_clutter,
    scatter_trees,
)
from assurance.scenes.houses import houses
from assurance.scenes.lookalikes import add_ground_lookalikes, add_object_lookalikes
from assurance.scenes.styles import pick
from assurance.scenes.world import Look
from el.classes.labels import CLASS_IDS

CLUTTER = CLASS_IDS["clutter"]
LOW_VEG = CLASS_IDS["low_vegetation"]
ROAD = CLASS_IDS["road"]

Filler = Callable[[Builder, float, float, float, float], None]


def fill_block(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Choose a block type by the style's weights (small blocks become lawns or plazas) and fill it."""
    st, rng = b.style, b.rng
    names = list(st.blocks)
    weights = np.array([st.blocks[n] for n in names], dtype=float)
    kind = names[int(rng.choice(len(names), p=weights / weights.sum()))]
    if min(a1 - a0, b1 - b0) < 18:
        kind = str(rng.choice(["lawn", "plaza", "parking"]))
    FILLERS[kind](b, a0, a1, b0, b1)


# -- block types ---------------------------------------------------------------------------------
def perimeter(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Buildings along the block edges around a courtyard (lawn, paving or parking)."""
    rng, st = b.rng, b.style
    depth = float(rng.uniform(9, 16))
    court_kind = str(rng.choice(["lawn", "paved", "parking"], p=[0.45, 0.35, 0.2]))
    base = lawn_look(b) if court_kind == "lawn" else paved_look(b)
    ground_region(b, a0, a1, b0, b1, LOW_VEG if court_kind == "lawn" else CLUTTER, base)
    if min(a1 - a0, b1 - b0) < 2 * depth + 10:
        _row_of_buildings(b, a0, a1, b0, b1, along_a=(a1 - a0) >= (b1 - b0))
        return
    _row_of_buildings(b, a0, a1, b0, b0 + depth, along_a=True)
    _row_of_buildings(b, a0, a1, b1 - depth, b1, along_a=True)
    _row_of_buildings(b, a0, a0 + depth, b0 + depth, b1 - depth, along_a=False)
    _row_of_buildings(b, a1 - depth, a1, b0 + depth, b1 - depth, along_a=False)
    ca0, ca1, cb0, cb1 = a0 + depth + 1, a1 - depth - 1, b0 + depth + 1, b1 - depth - 1
    if court_kind == "paved":
        add_ground_lookalikes(b, "perimeter", ca0, ca1, cb0, cb1, base)
    if court_kind == "parking":
        park_cars_rows(b, ca0, ca1, cb0, cb1, st.parked_fill, lines=rng.random() < 0.6)
    elif court_kind == "lawn":
        scatter_trees(b, ca0, ca1, cb0, cb1, 0.6)
        scatter_bushes(b, ca0, ca1, cb0, cb1, 0.5)
    else:
        scatter_trees(b, ca0, ca1, cb0, cb1, 0.25)
        scatter_clutter(b, ca0, ca1, cb0, cb1, int(rng.integers(0, 4)), ["bin", "bench", "dumpster", "pallets"])
        park_cars_rows(b, ca0, ca1, cb0, cb0 + 6, 0.4, lines=False)
    add_object_lookalikes(b, "perimeter", ca0, ca1, cb0, cb1)
    props.people_in_local(b, ca0, ca1, cb0, cb1, st.people_per_100m2 * 0.5)


def _row_of_buildings(b: Builder, a0: float, a1: float, b0: float, b1: float, *, along_a: bool) -> None:
    """Split a strip into lots along its length, one building per lot, sometimes a gap."""
    rng, st = b.rng, b.style
    s0, s1 = (a0, a1) if along_a else (b0, b1)
    s = s0
    while s < s1 - 4:
        ln = float(rng.uniform(10, 32))
        if s1 - (s + ln) < 8:
            ln = s1 - s
        if rng.random() < 0.08:
            s += ln
            continue
        h = float(np.clip(rng.uniform(*st.building_height) * rng.uniform(0.8, 1.15), 4.0, 25.0))
        pitched = rng.random() < st.pitched_prob
        if along_a:
            ca, cb, w, l, ang = (s + s + ln) / 2, (b0 + b1) / 2, ln, b1 - b0, b.phi
        else:
            ca, cb, w, l, ang = (a0 + a1) / 2, (s + s + ln) / 2, ln, a1 - a0, b.phi + math.pi / 2
        x, y = b.to_world(ca, cb)
        if pitched and w < l:
            w, l, ang = l, w, ang + math.pi / 2
        props.add_building(b, x, y, w - 0.02, l - 0.02, ang, h, style=props.BuildingStyle(pitched=pitched))
        s += ln


def _paving_bands(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Contrasting paving: a border band and sometimes a grid of bands across the square (clutter)."""
    rng = b.rng
    look = paved_look(b)
    bw = float(rng.uniform(1.0, 2.5))
    bands = [b.rect(a0, a1, b0, b0 + bw), b.rect(a0, a1, b1 - bw, b1),
             b.rect(a0, a0 + bw, b0, b1), b.rect(a1 - bw, a1, b0, b1)]
    if rng.random() < 0.5:
        step, w = float(rng.uniform(7, 16)), float(rng.uniform(0.5, 1.2))
        bands += [b.rect(a, a + w, b0, b1) for a in np.arange(a0 + step, a1 - step / 2, step)]
        bands += [b.rect(a0, a1, c, c + w) for c in np.arange(b0 + step, b1 - step / 2, step)]
    b.world.add_region(bands, CLUTTER, look, L_DETAIL)


def _tree_rows(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """One or two straight rows of evenly spaced trees (squares and forecourts)."""
    rng = b.rng
    spacing = float(rng.uniform(5.5, 9.0))
    radius = float(rng.uniform(*b.style.tree_size))
    for _ in range(int(rng.integers(1, 3))):
        if rng.random() < 0.5:
            c = float(rng.uniform(b0 + 3, b1 - 3))
            for a in np.arange(a0 + spacing / 2, a1 - 1, spacing):
                props.tree_at_local(b, float(a), c, radius * float(rng.uniform(0.85, 1.15)))
        else:
            c = float(rng.uniform(a0 + 3, a1 - 3))
            for bb in np.arange(b0 + spacing / 2, b1 - 1, spacing):
                props.tree_at_local(b, c, float(bb), radius * float(rng.uniform(0.85, 1.15)))


def _service_road(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """A narrow asphalt lane across the block (road: a thin forbidden strip, often under trees)."""
    rng, pal = b.rng, b.palette
    width = float(rng.uniform(3.0, 4.5))
    look = Look(str(rng.choice(["asphalt", "asphalt_worn"])), pick(rng, pal.asphalt + pal.lot_asphalt, 0.08, 0.015))
    ra0, ra1, rb0, rb1 = b.strip_across(a0, a1, b0, b1, width)
    if ra1 - ra0 > rb1 - rb0:  # along a
        c = (rb0 + rb1) / 2
        trees = [(float(a), c + (width / 2 + 1.5) * float(rng.choice([-1, 1])))
                 for a in np.arange(a0 + 4, a1 - 2, float(rng.uniform(8, 14)))]
    else:
        c = (ra0 + ra1) / 2
        trees = [(c + (width / 2 + 1.5) * float(rng.choice([-1, 1])), float(bb))
                 for bb in np.arange(b0 + 4, b1 - 2, float(rng.uniform(8, 14)))]
    b.world.add_region(b.rect(ra0, ra1, rb0, rb1), ROAD, look, L_DETAIL2)
    b.occupy_local(ra0, ra1, rb0, rb1)
    for a, bb in trees:
        if rng.random() < 0.6:
            props.tree_at_local(b, a, bb)


def towers(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """One to three large buildings on a paved plaza with planters, trees, furniture and people."""
    rng, st = b.rng, b.style
    ground = paved_look(b)
    ground_region(b, a0, a1, b0, b1, CLUTTER, ground)
    if rng.random() < 0.6:
        _paving_bands(b, a0, a1, b0, b1)
    add_ground_lookalikes(b, "towers", a0, a1, b0, b1, ground)
    n = int(rng.integers(1, 4))
    for _ in range(n * 3):
        if n == 0:
            break
        w = float(rng.uniform(14, min(45, a1 - a0 - 6)))
        l = float(rng.uniform(12, min(40, b1 - b0 - 6)))
        if w < 8 or l < 8:
            break
        ca = float(rng.uniform(a0 + 3 + w / 2, a1 - 3 - w / 2))
        cb = float(rng.uniform(b0 + 3 + l / 2, b1 - 3 - l / 2))
        if not b.free_rect_local(ca - w / 2 - 3, ca + w / 2 + 3, cb - l / 2 - 3, cb + l / 2 + 3):
            continue
        h = float(np.clip(rng.uniform(*st.building_height) * rng.uniform(1.0, 1.4), 6.0, 25.0))
        x, y = b.to_world(ca, cb)
        props.add_building(b, x, y, w, l, b.phi, h)
        n -= 1
    _planters(b, a0, a1, b0, b1, int(rng.integers(2, 8)))
    if rng.random() < 0.4:
        _tree_rows(b, a0, a1, b0, b1)
    scatter_clutter(b, a0, a1, b0, b1, int(rng.integers(2, 8)), ["bench", "bin", "bollard", "kiosk", "umbrella"])
    props.people_in_local(b, a0, a1, b0, b1, st.people_per_100m2)
    if rng.random() < 0.4:
        park_cars_rows(b, a0 + 2, a1 - 2, b0 + 1, b0 + 12, st.parked_fill)


def _planters(b: Builder, a0: float, a1: float, b0: float, b1: float, n: int) -> None:
    rng, pal = b.rng, b.palette
    for _ in range(n):
        sa, sb = float(rng.uniform(2, 8)), float(rng.uniform(2, 5))
        ca, cb = float(rng.uniform(a0 + sa, a1 - sa)), float(rng.uniform(b0 + sb, b1 - sb))
        if not b.free_local(ca, cb, max(sa, sb) / 2 + 0.5):
            continue
        look = Look(str(rng.choice(["grass", "shrub", "soil"], p=[0.5, 0.3, 0.2])),
                    pick(rng, pal.grass + pal.shrub, 0.1))
        label = CLUTTER if look.material == "soil" else LOW_VEG
        ground_region(b, ca - sa / 2, ca + sa / 2, cb - sb / 2, cb + sb / 2, label, look, L_DETAIL2)
        if rng.random() < 0.7:
            props.tree_at_local(b, ca, cb)


def park(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Lawn with paths, clustered trees, bushes, a pond or playground, benches and people."""
    rng, st, pal, w = b.rng, b.style, b.palette, b.world
    ground_region(b, a0, a1, b0, b1, LOW_VEG, lawn_look(b))
    for _ in range(int(rng.integers(1, 4))):
        blob_region(b, float(rng.uniform(a0, a1)), float(rng.uniform(b0, b1)), float(rng.uniform(3, 12)),
                    float(rng.uniform(2, 8)), LOW_VEG if rng.random() < 0.6 else CLUTTER,
                    Look(str(rng.choice(["grass", "soil"])), pick(rng, pal.dry_grass + pal.soil, 0.1)))
    path_look = Look(str(rng.choice(["gravel", "pavers", "slabs", "asphalt"])),
                     pick(rng, pal.gravel + pal.paving + pal.lot_asphalt, 0.1))
    paths = []
    for _ in range(int(rng.integers(1, 4))):
        width = float(rng.uniform(2, 5))
        if rng.random() < 0.5:
            c = float(rng.uniform(b0 + 5, b1 - 5))
            paths.append(b.rect(a0, a1, c - width / 2, c + width / 2))
        else:
            c = float(rng.uniform(a0 + 5, a1 - 5))
            paths.append(b.rect(c - width / 2, c + width / 2, b0, b1))
    w.add_region(paths, CLUTTER, path_look, L_DETAIL2)
    if rng.random() < 0.3 and min(a1 - a0, b1 - b0) > 25:
        _service_road(b, a0, a1, b0, b1)
    add_ground_lookalikes(b, "park", a0, a1, b0, b1)
    if rng.random() < 0.35:
        ca, cb = float(rng.uniform(a0 + 12, a1 - 12)), float(rng.uniform(b0 + 10, b1 - 10))
        if b.free_local(ca, cb, 6):
            blob_region(b, ca, cb, float(rng.uniform(5, 12)), float(rng.uniform(4, 9)), CLUTTER,
                        Look("water", pick(rng, pal.water, 0.1)), L_DETAIL2)
            b.occupy_local(ca - 6, ca + 6, cb - 5, cb + 5)
    if rng.random() < 0.35:
        ca, cb = float(rng.uniform(a0 + 8, a1 - 8)), float(rng.uniform(b0 + 8, b1 - 8))
        if b.free_local(ca, cb, 5):
            ground_region(b, ca - 7, ca + 7, cb - 5, cb + 5, CLUTTER, Look("sand", pick(rng, pal.sand, 0.1)), L_DETAIL2)
            scatter_clutter(b, ca - 7, ca + 7, cb - 5, cb + 5, int(rng.integers(2, 6)), ["play"])
            props.people_in_local(b, ca - 7, ca + 7, cb - 5, cb + 5, 3.0)
    add_object_lookalikes(b, "park", a0, a1, b0, b1)
    scatter_trees(b, a0, a1, b0, b1, 0.9, clustered=True)
    scatter_bushes(b, a0, a1, b0, b1, 0.4)
    scatter_clutter(b, a0, a1, b0, b1, int(rng.integers(1, 6)), ["bench", "bin", "bench"])
    props.people_in_local(b, a0, a1, b0, b1, st.people_per_100m2 * 0.6)


def lawn(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """An open lawn with scattered trees, a path, sometimes a small building."""
    rng, st, pal = b.rng, b.style, b.palette
    ground_region(b, a0, a1, b0, b1, LOW_VEG, lawn_look(b))
    if rng.random() < 0.3 and min(a1 - a0, b1 - b0) > 25:
        _service_road(b, a0, a1, b0, b1)
    elif rng.random() < 0.5 and b1 - b0 > 10:
        c = float(rng.uniform(b0 + 3, b1 - 3))
        ground_region(b, a0, a1, c - 1.5, c + 1.5, CLUTTER, paved_look(b), L_DETAIL2)
    add_ground_lookalikes(b, "lawn", a0, a1, b0, b1)
    if rng.random() < 0.3 and min(a1 - a0, b1 - b0) > 25:
        ca, cb = (a0 + a1) / 2, (b0 + b1) / 2
        bw, bl = float(rng.uniform(8, 16)), float(rng.uniform(8, 14))
        if b.free_rect_local(ca - bw / 2 - 1, ca + bw / 2 + 1, cb - bl / 2 - 1, cb + bl / 2 + 1):
            x, y = b.to_world(ca, cb)
            props.add_building(b, x, y, bw, bl, b.phi, float(rng.uniform(4, 9)),
                               style=props.BuildingStyle(pitched=rng.random() < st.pitched_prob))
    if rng.random() < 0.4:
        blob_region(b, float(rng.uniform(a0, a1)), float(rng.uniform(b0, b1)), float(rng.uniform(3, 10)),
                    float(rng.uniform(2, 6)), CLUTTER, Look("soil", pick(rng, pal.soil, 0.1)))
    add_object_lookalikes(b, "lawn", a0, a1, b0, b1)
    scatter_trees(b, a0, a1, b0, b1, 0.35)
    scatter_bushes(b, a0, a1, b0, b1, 0.3)
    props.people_in_local(b, a0, a1, b0, b1, st.people_per_100m2 * 0.3)


def plaza(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """A paved square: fountain, planters with trees, umbrellas, kiosks, benches and crowds."""
    rng, st, pal = b.rng, b.style, b.palette
    ground = paved_look(b)
    ground_region(b, a0, a1, b0, b1, CLUTTER, ground)
    if rng.random() < 0.7:
        _paving_bands(b, a0, a1, b0, b1)
    add_ground_lookalikes(b, "plaza", a0, a1, b0, b1, ground)
    if rng.random() < 0.5:
        _tree_rows(b, a0, a1, b0, b1)
    if rng.random() < 0.5:
        inner = paved_look(b)
        m = float(rng.uniform(3, 8))
        if min(a1 - a0, b1 - b0) > 2 * m + 6:
            ground_region(b, a0 + m, a1 - m, b0 + m, b1 - m, CLUTTER, inner, L_DETAIL)
    if rng.random() < 0.4:
        ca, cb = (a0 + a1) / 2, (b0 + b1) / 2
        r = float(rng.uniform(3, 7))
        if b.free_local(ca, cb, r):
            blob_region(b, ca, cb, r + 0.6, r + 0.6, CLUTTER, Look("curb", pick(rng, pal.paving, 0.05)), L_DETAIL2)
            poly = ellipse(ca, cb, r, r, 0, n=24)
            b.world.add_region(b.origin + poly[:, :1] * b.ea + poly[:, 1:] * b.eb, CLUTTER,
                               Look("water", pick(rng, pal.water, 0.1)), L_LOT_PAINT)
            b.occupy_local(ca - r, ca + r, cb - r, cb + r)
    add_object_lookalikes(b, "plaza", a0, a1, b0, b1)
    _planters(b, a0, a1, b0, b1, int(rng.integers(2, 10)))
    scatter_trees(b, a0, a1, b0, b1, 0.12)
    scatter_clutter(b, a0, a1, b0, b1, int(rng.integers(3, 14)),
                    ["bench", "bin", "umbrella", "umbrella", "kiosk", "bollard"])
    props.people_in_local(b, a0, a1, b0, b1, st.people_per_100m2 * 2.5)


def parking(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """An asphalt car park (clutter, not road) with bay lines, static cars, islands and trees."""
    rng, st, pal = b.rng, b.style, b.palette
    ground_region(b, a0, a1, b0, b1, CLUTTER, Look(str(rng.choice(["asphalt", "asphalt_worn"])),
                                                   pick(rng, pal.lot_asphalt + pal.asphalt, 0.08, 0.015)))
    if rng.random() < 0.5:  # planted edge
        ground_region(b, a0, a1, b0, b0 + 2.5, LOW_VEG, lawn_look(b), L_DETAIL)
        for a in np.arange(a0 + 4, a1 - 2, float(rng.uniform(8, 14))):
            props.tree_at_local(b, float(a), b0 + 1.25)
        b0 += 2.5
    park_cars_rows(b, a0 + 1, a1 - 1, b0 + 1, b1 - 1, float(np.clip(st.parked_fill + rng.normal(0, 0.2), 0.2, 0.95)),
                   lines=rng.random() < 0.85)
    props.people_in_local(b, a0, a1, b0, b1, st.people_per_100m2 * 0.3)


def industrial(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Large warehouses on a concrete, gravel or soil yard with containers, trucks, pallets and cars."""
    rng, st, pal = b.rng, b.style, b.palette
    yard = str(rng.choice(["concrete_slab", "gravel", "soil", "asphalt_worn"], p=[0.35, 0.25, 0.15, 0.25]))
    colours = {"concrete_slab": pal.paving, "gravel": pal.gravel, "soil": pal.soil, "asphalt_worn": pal.lot_asphalt}
    ground_region(b, a0, a1, b0, b1, CLUTTER, Look(yard, pick(rng, colours[yard], 0.08)))
    for _ in range(int(rng.integers(1, 4))):
        blob_region(b, float(rng.uniform(a0, a1)), float(rng.uniform(b0, b1)), float(rng.uniform(4, 14)),
                    float(rng.uniform(3, 9)), CLUTTER, Look(str(rng.choice(["soil", "gravel"])),
                                                            pick(rng, pal.soil + pal.gravel, 0.1)))
    add_ground_lookalikes(b, "industrial", a0, a1, b0, b1)
    for _ in range(int(rng.integers(1, 3)) * 3):
        w = float(rng.uniform(20, min(70, a1 - a0 - 6)))
        l = float(rng.uniform(15, min(45, b1 - b0 - 6)))
        if w < 10 or l < 10:
            break
        ca = float(rng.uniform(a0 + 3 + w / 2, a1 - 3 - w / 2))
        cb = float(rng.uniform(b0 + 3 + l / 2, b1 - 3 - l / 2))
        if not b.free_rect_local(ca - w / 2 - 4, ca + w / 2 + 4, cb - l / 2 - 4, cb + l / 2 + 4):
            continue
        x, y = b.to_world(ca, cb)
        props.add_building(b, x, y, w, l, b.phi, float(np.clip(rng.uniform(*st.building_height), 4.0, 16.0)),
                           style=props.BuildingStyle(pitched=rng.random() < 0.15, industrial=True))
    add_object_lookalikes(b, "industrial", a0, a1, b0, b1)
    scatter_clutter(b, a0, a1, b0, b1, int(rng.integers(2, 12)), ["container", "pallets", "dumpster", "container"])
    for _ in range(int(rng.integers(0, 4))):
        a, c = float(rng.uniform(a0 + 6, a1 - 6)), float(rng.uniform(b0 + 4, b1 - 4))
        if b.free_local(a, c, 6):
            x, y = b.to_world(a, c)
            props.add_car(b, x, y, b.phi + float(rng.choice([0, math.pi / 2])), moving=False, kind="truck")
    if rng.random() < 0.6:
        park_cars_rows(b, a0 + 1, a1 - 1, b0 + 1, b0 + 12, st.parked_fill)
    scatter_bushes(b, a0, a1, b0, b1, 0.1)
    scatter_trees(b, a0, a1, b0, b1, 0.05)
    props.people_in_local(b, a0, a1, b0, b1, st.people_per_100m2)


def vacant(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Waste ground: soil, dry grass and gravel patches, shrubs, a few trees and debris."""
    rng, pal = b.rng, b.palette
    ground_region(b, a0, a1, b0, b1, CLUTTER, Look("soil", pick(rng, pal.soil, 0.1)))
    for _ in range(int(rng.integers(3, 9))):
        veg = rng.random() < 0.6
        blob_region(b, float(rng.uniform(a0, a1)), float(rng.uniform(b0, b1)), float(rng.uniform(3, 15)),
                    float(rng.uniform(2, 10)), LOW_VEG if veg else CLUTTER,
                    Look("grass" if veg else "gravel", pick(rng, (pal.dry_grass + pal.grass) if veg else pal.gravel,
                                                            0.1)))
    add_ground_lookalikes(b, "vacant", a0, a1, b0, b1)
    add_object_lookalikes(b, "vacant", a0, a1, b0, b1)
    scatter_bushes(b, a0, a1, b0, b1, 0.6)
    scatter_trees(b, a0, a1, b0, b1, 0.1, clustered=True)
    scatter_clutter(b, a0, a1, b0, b1, int(rng.integers(0, 6)), ["pallets", "container", "dumpster"])


def sports(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """A court or pitch with white lines (clutter) in a lawn, with spectators."""
    rng, pal, w = b.rng, b.palette, b.world
    ground_region(b, a0, a1, b0, b1, LOW_VEG, lawn_look(b))
    m = float(rng.uniform(3, 8))
    if min(a1 - a0, b1 - b0) < 2 * m + 10:
        return
    ca0, ca1, cb0, cb1 = a0 + m, a1 - m, b0 + m, b1 - m
    surface = Look("court", pick(rng, pal.court, 0.1)) if rng.random() < 0.7 else lawn_look(b)
    label = CLUTTER if surface.material == "court" else LOW_VEG
    ground_region(b, ca0, ca1, cb0, cb1, label, surface, L_DETAIL)
    lw = 0.12
    paint = Look("paint", pick(rng, pal.paint, 0.05))
    lines = [b.rect(ca0 + 1, ca1 - 1, cb0 + 1, cb0 + 1 + lw), b.rect(ca0 + 1, ca1 - 1, cb1 - 1 - lw, cb1 - 1),
             b.rect(ca0 + 1, ca0 + 1 + lw, cb0 + 1, cb1 - 1), b.rect(ca1 - 1 - lw, ca1 - 1, cb0 + 1, cb1 - 1),
             b.rect((ca0 + ca1) / 2 - lw / 2, (ca0 + ca1) / 2 + lw / 2, cb0 + 1, cb1 - 1)]
    w.add_region(lines, label, paint, L_DETAIL2)
    props.people_in_local(b, ca0, ca1, cb0, cb1, 0.4)
    add_object_lookalikes(b, "sports", a0, a1, b0, cb0)
    scatter_trees(b, a0, a1, b0, cb0, 0.3)


FILLERS: dict[str, Filler] = {f.__name__: f for f in (perimeter, towers, houses, park, lawn, plaza, parking,
                                                      industrial, vacant, sports)}
