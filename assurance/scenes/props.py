"""Object constructors: buildings, cars, people, trees, bushes, hedges and street furniture.

Each function adds the object's solids to the builder's world at a world position (metres) with
a heading (rad) and randomises its size and colours from the builder's style palette.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from assurance.scenes.builder import Builder
from assurance.scenes.styles import pick
from assurance.scenes.world import Block, Crown, Look
from el.classes.labels import CLASS_IDS

BUILDING = CLASS_IDS["building"]
ROAD = CLASS_IDS["road"]
STATIC_CAR = CLASS_IDS["static_car"]
MOVING_CAR = CLASS_IDS["moving_car"]
TREE = CLASS_IDS["tree"]
LOW_VEG = CLASS_IDS["low_vegetation"]
HUMAN = CLASS_IDS["human"]
CLUTTER = CLASS_IDS["clutter"]

SKIN = ((0.80, 0.62, 0.50), (0.62, 0.45, 0.34), (0.42, 0.30, 0.22))
HAIR = ((0.12, 0.10, 0.08), (0.30, 0.22, 0.14), (0.55, 0.45, 0.30), (0.60, 0.60, 0.60))


def _rot(dx: float, dy: float, angle: float) -> tuple[float, float]:
    c, s = math.cos(angle), math.sin(angle)
    return c * dx - s * dy, s * dx + c * dy


# -- buildings ------------------------------------------------------------------------------
def roof_look(b: Builder, *, pitched: bool, industrial: bool = False) -> Look:
    """A roof appearance: tiles for pitched roofs, otherwise membrane, gravel, concrete, metal or green."""
    pal, rng = b.palette, b.rng
    if pitched:
        return Look("roof_tiles", pick(rng, pal.roof_pitched, 0.1, 0.02))
    if industrial and rng.random() < 0.6:
        return Look("roof_metal", pick(rng, pal.roof, 0.08, 0.03))
    kind = rng.choice(["roof_membrane", "roof_gravel", "roof_concrete", "roof_green", "asphalt"],
                      p=[0.34, 0.2, 0.3, 0.06, 0.1])
    colours = pal.green_roof if kind == "roof_green" else pal.roof
    if kind == "asphalt":
        colours = pal.asphalt
    return Look(str(kind), pick(rng, colours, 0.1, 0.025))


def facade_look(b: Builder, *, industrial: bool = False, height: float = 10.0) -> Look:
    """A facade with a window grid; downtown towers sometimes get curtain walls."""
    pal, rng = b.palette, b.rng
    glass = pick(rng, pal.glass, 0.15, 0.03)
    if industrial:
        return Look("metal_wall", pick(rng, pal.roof + pal.facade, 0.1, 0.03))
    if height > 14 and rng.random() < 0.35:
        return Look("curtain_wall", pick(rng, pal.glass + pal.facade[:2], 0.1), cell_rgb=glass,
                    cell=(float(rng.uniform(1.4, 2.2)), float(rng.uniform(3.0, 3.8)), 0.46, 0.42))
    su, sv = float(rng.uniform(2.2, 4.2)), float(rng.uniform(2.9, 3.5))
    return Look("facade", pick(rng, pal.facade, 0.1, 0.03), cell_rgb=glass,
                cell=(su, sv, float(rng.uniform(0.16, 0.34)), float(rng.uniform(0.16, 0.3))))


@dataclass(frozen=True, kw_only=True)
class BuildingStyle:
    """How a building is built, besides where and how big: a ``pitched`` roof (its ridge along the width), an
    ``industrial`` look, rooftop ``equipment`` and a ``parapet`` on a large flat roof (each drawn, not certain), and
    ``roof``: an appearance instead of the drawn one (look-alike sheds)."""

    pitched: bool = False
    industrial: bool = False
    equipment: bool = True
    roof: Look | None = None
    parapet: bool = True


def add_building(b: Builder, cx: float, cy: float, w: float, l: float, angle: float, h: float, *,
                 style: BuildingStyle | None = None) -> Block:
    """A building block (ridge along ``w`` when pitched) with rooftop equipment on flat roofs, built as ``style``
    says (None: :class:`BuildingStyle`'s defaults)."""
    style = style or BuildingStyle()
    pitched, industrial, equipment, roof, parapet = (style.pitched, style.industrial, style.equipment, style.roof,
                                                     style.parapet)
    rng = b.rng
    gable = 0.0
    if pitched:
        gable = (l / 2) * math.tan(math.radians(rng.uniform(22, 38)))
        gable = min(gable, 0.9 * h + 2.0)
    block = b.world.add_block(Block(cx, cy, w, l, angle, 0.0, h, BUILDING,
                                    roof or roof_look(b, pitched=pitched, industrial=industrial),
                                    facade_look(b, industrial=industrial, height=h), gable=gable, kind="building"))
    b.occupy_rect_world(cx, cy, w, l, angle, building=True)
    if parapet and not pitched and w > 6 and l > 6 and rng.random() < 0.6:
        add_parapet(b, block)
    if equipment and not pitched and w * l > 60:
        add_roof_equipment(b, block)
    return block


def add_parapet(b: Builder, bld: Block) -> None:
    """A low wall along the roof edge (building): a bright or dark rim with a thin shadow line."""
    rng = b.rng
    t = float(rng.uniform(0.25, 0.45))
    h = float(rng.uniform(0.4, 1.1))
    k = float(rng.uniform(0.8, 1.25))
    rgb = tuple(min(0.95, c * k) for c in bld.side.rgb)
    look = Look("roof_concrete", rgb)  # type: ignore[arg-type]
    for du, dv, w, l in ((0.0, -(bld.l - t) / 2, bld.w, t), (0.0, (bld.l - t) / 2, bld.w, t),
                         (-(bld.w - t) / 2, 0.0, t, bld.l - 2 * t), ((bld.w - t) / 2, 0.0, t, bld.l - 2 * t)):
        dx, dy = _rot(du, dv, bld.angle)
        b.world.add_block(Block(bld.cx + dx, bld.cy + dy, w, l, bld.angle, bld.h, h, BUILDING, look, look,
                                kind="equipment"))


def add_roof_equipment(b: Builder, bld: Block) -> None:
    """AC units, stair/lift housings and solar rows on a flat roof (all labelled building)."""
    rng, pal = b.rng, b.palette
    area = bld.w * bld.l
    margin = 1.0
    n = int(rng.poisson(area / 140))
    for _ in range(min(n, 10)):
        big = rng.random() < 0.2
        if big:
            ew, el = rng.uniform(2.5, 5.0), rng.uniform(2.5, 4.5)
        else:
            ew, el = rng.uniform(0.8, 2.6), rng.uniform(0.8, 2.0)
        eh = rng.uniform(2.2, 3.2) if big else rng.uniform(0.5, 1.8)
        if ew > bld.w - 2 * margin or el > bld.l - 2 * margin:
            continue
        du = rng.uniform(-(bld.w - ew) / 2 + margin, (bld.w - ew) / 2 - margin)
        dv = rng.uniform(-(bld.l - el) / 2 + margin, (bld.l - el) / 2 - margin)
        dx, dy = _rot(du, dv, bld.angle)
        col = pick(rng, pal.roof + ((0.7, 0.7, 0.7),), 0.1)
        look = Look("metal", col)
        b.world.add_block(Block(bld.cx + dx, bld.cy + dy, ew, el, bld.angle, bld.h, eh, BUILDING,
                                look, Look("metal", col), kind="equipment"))
    if area > 200 and rng.random() < 0.25:
        rows = int(rng.integers(2, 6))
        pw = min(bld.w - 3, rng.uniform(6, 20))
        for r in range(rows):
            dv = -bld.l / 2 + 2 + r * 2.6
            if dv + 1.5 > bld.l / 2 - 1:
                break
            dx, dy = _rot(0.0, dv + 0.8, bld.angle)
            panel = Look("solar", (0.12, 0.15, 0.24))
            b.world.add_block(Block(bld.cx + dx, bld.cy + dy, pw, 1.7, bld.angle, bld.h, 0.35, BUILDING,
                                    panel, Look("metal", (0.5, 0.5, 0.5)), kind="equipment"))


# -- vehicles ---------------------------------------------------------------------------------
CAR_TYPES = {
    # length, width, body h, cabin length share, cabin h, cabin offset (share of length, + = rear)
    "sedan": (4.5, 1.8, 0.9, 0.52, 0.5, 0.08),
    "hatch": (4.0, 1.75, 0.9, 0.55, 0.55, 0.12),
    "suv": (4.75, 1.9, 1.05, 0.6, 0.62, 0.08),
    "van": (5.2, 2.0, 1.2, 0.78, 0.85, 0.05),
}


def add_car(b: Builder, x: float, y: float, heading: float, *, moving: bool, kind: str | None = None) -> None:
    """A car: body box and a glazed cabin box on top (trucks and buses get bigger boxes)."""
    rng, pal = b.rng, b.palette
    label = MOVING_CAR if moving else STATIC_CAR
    if kind is None:
        kind = str(rng.choice(["sedan", "hatch", "suv", "van", "truck", "bus"],
                              p=[0.38, 0.22, 0.22, 0.1, 0.05, 0.03]))
    paint = pick(rng, pal.car, 0.08, 0.02)
    body_look = Look("car_paint", paint)
    glass = Look("car_glass", pick(rng, pal.glass, 0.2, 0.02))
    if kind in ("truck", "bus"):
        length = rng.uniform(7.5, 10.0) if kind == "truck" else rng.uniform(10.5, 12.5)
        width = rng.uniform(2.35, 2.55)
        height = rng.uniform(2.9, 3.6)
        top = Look("car_paint", pick(rng, pal.car[:3] + pal.roof[:2], 0.08))
        b.world.add_block(Block(x, y, length, width, heading, 0.0, height, label, top, body_look, kind="car"))
        b.occupy_rect_world(x, y, length, width, heading)
        return
    length, width, bh, cl, ch, coff = CAR_TYPES[kind]
    length *= rng.uniform(0.94, 1.06)
    width *= rng.uniform(0.96, 1.04)
    dark = Look("car_paint", (0.07, 0.07, 0.08))
    b.world.add_block(Block(x, y, 0.9 * length, 0.94 * width, heading, 0.0, 0.42, label, dark, dark, kind="car"),
                      register=False)
    b.world.add_block(Block(x, y, length, width, heading, 0.3, bh - 0.3, label, body_look, body_look, kind="car",
                            taper=(0.96, 0.9)), register=True)
    dx, dy = _rot(-coff * length, 0.0, heading)
    roof = body_look if rng.random() < 0.85 else Look("car_glass", pick(rng, pal.glass))
    b.world.add_block(Block(x + dx, y + dy, cl * length, 0.82 * width, heading, bh, ch, label, roof, glass,
                            kind="cabin", taper=(float(rng.uniform(0.6, 0.75)), 0.82)))
    b.occupy_rect_world(x, y, length, width, heading)


# -- people -----------------------------------------------------------------------------------
def add_person(b: Builder, x: float, y: float) -> None:
    """A standing person: 0.5 m x 0.3 m body, 1.7 m tall with the head."""
    rng, pal = b.rng, b.palette
    heading = rng.uniform(0, 2 * math.pi)
    top = pick(rng, pal.clothing, 0.15, 0.04)
    height = rng.uniform(1.35, 1.5)
    b.world.add_block(Block(x, y, rng.uniform(0.42, 0.55), rng.uniform(0.25, 0.32), heading, 0.0, height, HUMAN,
                            Look("cloth", top), Look("cloth", pick(rng, pal.clothing, 0.15, 0.04)), kind="person"))
    hair = Look("cloth", pick(rng, HAIR, 0.1))
    b.world.add_block(Block(x, y, 0.2, 0.22, heading, height, rng.uniform(0.2, 0.27), HUMAN, hair,
                            Look("cloth", pick(rng, SKIN, 0.1)), kind="head"))
    b.occupy_circle_world(x, y, 0.35)


def add_people(b: Builder, x: float, y: float, n: int, spread: float = 1.2) -> None:
    """A small group of people around (x, y), each only where the ground is free."""
    for _ in range(n):
        px, py = x + b.rng.normal(0, spread), y + b.rng.normal(0, spread)
        if b.free_world(px, py, 0.4):
            add_person(b, px, py)



def people_in_local(b: Builder, a0: float, a1: float, b0: float, b1: float, density: float) -> None:
    """Scatter people (groups of 1-4) over a local rectangle at ``density`` per 100 m^2."""
    area = max(0.0, (a1 - a0) * (b1 - b0))
    n_groups = int(b.rng.poisson(density * area / 100 / 1.8))
    for _ in range(n_groups):
        a, c = b.rng.uniform(a0, a1), b.rng.uniform(b0, b1)
        x, y = b.to_world(a, c)
        add_people(b, x, y, int(b.rng.integers(1, 5)), spread=0.9)


# -- vegetation -------------------------------------------------------------------------------
def add_tree(b: Builder, x: float, y: float, radius: float, *, trunk_h: float | None = None,
             colour: tuple[float, float, float] | None = None) -> None:
    """A tree: trunk block and a crown of 5-10 ellipsoid blobs (radius = crown radius in metres)."""
    rng, pal = b.rng, b.palette
    if trunk_h is None:
        trunk_h = rng.uniform(1.2, 2.4) + 0.08 * radius
    rz_scale = rng.uniform(0.65, 0.95)
    centre_z = trunk_h + radius * rz_scale * 0.75
    n = int(rng.integers(5, 11))
    blobs = [(x, y, centre_z, radius * 0.62, radius * 0.62 * rz_scale)]
    for _ in range(n - 1):
        ang = rng.uniform(0, 2 * math.pi)
        d = rng.uniform(0.2, 0.62) * radius
        r = radius * rng.uniform(0.3, 0.5)
        dz = rng.uniform(-0.4, 0.45) * radius * rz_scale
        blobs.append((x + d * math.cos(ang), y + d * math.sin(ang), centre_z + dz, r, r * rz_scale * 1.1))
    look = Look("foliage", colour or pick(rng, pal.tree, 0.14, 0.035))
    trunk_w = float(np.clip(0.1 * radius, 0.2, 0.5))
    b.world.add_block(Block(x, y, trunk_w, trunk_w, rng.uniform(0, math.pi), 0.0, centre_z, TREE,
                            Look("bark", (0.32, 0.27, 0.22)), Look("bark", (0.30, 0.25, 0.2)), kind="trunk"))
    b.world.add_crown(Crown(np.array(blobs, dtype=np.float64), TREE, look))
    b.occupy_circle_world(x, y, max(0.5, trunk_w))


def add_bush(b: Builder, x: float, y: float, radius: float) -> None:
    """A low bush (low vegetation): a few blobs sitting on the ground."""
    rng, pal = b.rng, b.palette
    n = int(rng.integers(1, 4))
    blobs = []
    for _ in range(n):
        r = radius * rng.uniform(0.6, 1.0)
        blobs.append((x + rng.normal(0, radius * 0.4), y + rng.normal(0, radius * 0.4), r * 0.55, r, r * 0.6))
    colours = pal.shrub + pal.tree if rng.random() < 0.5 else pal.shrub
    b.world.add_crown(Crown(np.array(blobs), LOW_VEG, Look("shrub", pick(rng, colours, 0.14, 0.035))))


def add_hedge(b: Builder, cx: float, cy: float, length: float, angle: float) -> None:
    """A trimmed hedge: a low-vegetation box 0.6-1.1 m wide and 0.7-1.8 m tall."""
    rng, pal = b.rng, b.palette
    col = pick(rng, pal.shrub + pal.tree, 0.12, 0.03)
    look = Look("shrub", col)
    side = Look("shrub", tuple(c * 0.85 for c in col))
    b.world.add_block(Block(cx, cy, length, rng.uniform(0.6, 1.1), angle, 0.0, rng.uniform(0.7, 1.8), LOW_VEG,
                            look, side, kind="hedge"))



def tree_at_local(b: Builder, a: float, c: float, radius: float | None = None, **kw: object) -> bool:
    """Plant a tree at local (a, c) if its trunk spot is free and its crown clears buildings."""
    if radius is None:
        radius = float(b.rng.uniform(*b.style.tree_size))
    if not b.free_local(a, c, 0.6) or not b.free_local(a, c, 0.75 * radius, buildings_only=True):
        return False
    x, y = b.to_world(a, c)
    add_tree(b, x, y, radius, **kw)  # type: ignore[arg-type]
    return True


# -- street furniture and other clutter ---------------------------------------------------------
def add_clutter(b: Builder, x: float, y: float, heading: float, kind: str) -> None:
    """Benches, bins, lamps, kiosks, umbrellas, containers, dumpsters, pallets and sheds (clutter)."""
    rng, pal = b.rng, b.palette
    w = b.world

    def box(size: tuple[float, float, float], top: Look, side: Look | None = None, *, z0: float = 0.0,
            at: tuple[float, float] = (0.0, 0.0), label: int = CLUTTER) -> None:
        """A box of ``size`` (width, length, height) from height ``z0``, ``at`` (dx, dy) from the object."""
        bw, bl, h = size
        ox, oy = _rot(at[0], at[1], heading)
        w.add_block(Block(x + ox, y + oy, bw, bl, heading, z0, h, label, top, side or top, kind="clutter"))

    col = pick(rng, pal.clutter, 0.12, 0.03)
    if kind == "bench":
        box((1.8, 0.55, 0.45), Look("wood", pick(rng, ((0.50, 0.36, 0.24), (0.40, 0.40, 0.40)), 0.1)))
    elif kind == "bin":
        box((0.6, 0.6, 1.0), Look("metal", pick(rng, ((0.2, 0.22, 0.24), (0.3, 0.4, 0.3)), 0.1)))
    elif kind == "lamp":
        grey = Look("metal", pick(rng, ((0.35, 0.35, 0.37), (0.55, 0.55, 0.55)), 0.1))
        height = rng.uniform(6, 9)
        box((0.18, 0.18, height), grey)
        box((1.2, 0.3, 0.25), grey, z0=height, at=(0.6, 0))
    elif kind == "bollard":
        box((0.2, 0.2, 0.9), Look("metal", (0.3, 0.3, 0.3)))
    elif kind == "kiosk":
        box((rng.uniform(2.5, 4.0), rng.uniform(2.0, 3.0), rng.uniform(2.4, 3.0)), Look("metal", col),
            Look("facade", col, cell_rgb=(0.3, 0.35, 0.4), cell=(1.2, 100.0, 0.4, 0.5)))
    elif kind == "umbrella":
        fabric = Look("fabric", pick(rng, ((0.85, 0.85, 0.82), (0.7, 0.2, 0.2), (0.2, 0.35, 0.6),
                                           (0.9, 0.75, 0.3), (0.3, 0.5, 0.3)), 0.08))
        size = rng.uniform(2.2, 3.5)
        box((0.08, 0.08, 2.2), Look("metal", (0.4, 0.4, 0.4)))
        box((size, size, 0.35), fabric, z0=2.2)
    elif kind == "container":
        box((6.06, 2.44, 2.6), Look("metal_wall", col), Look("metal_wall", col))
    elif kind == "dumpster":
        box((rng.uniform(1.8, 3.5), rng.uniform(1.3, 2.0), rng.uniform(1.1, 1.6)),
            Look("metal", pick(rng, pal.car + pal.clutter, 0.1)))
    elif kind == "pallets":
        box((rng.uniform(1.0, 2.5), rng.uniform(1.0, 2.0), rng.uniform(0.4, 1.6)), Look("wood", col))
    elif kind == "shed":
        # a garden shed is a (small) building
        box((rng.uniform(2.0, 3.5), rng.uniform(2.0, 3.0), rng.uniform(2.0, 2.6)),
            roof_look(b, pitched=False), Look("wood", col), label=BUILDING)
    elif kind == "play":
        box((rng.uniform(1.0, 3.0), rng.uniform(1.0, 2.5), rng.uniform(0.8, 2.5)),
            Look("metal", pick(rng, ((0.8, 0.3, 0.2), (0.2, 0.5, 0.8), (0.9, 0.8, 0.2)), 0.1)))
    else:
        raise ValueError(f"unknown clutter kind {kind!r}")
    b.occupy_circle_world(x, y, 1.0)
