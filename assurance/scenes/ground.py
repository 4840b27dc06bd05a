"""Ground helpers of the block fillers: paved and lawn looks, ground patches, scattered trees, bushes,
clutter and rows of parked cars, each inside a block's local rectangle [a0, a1] x [b0, b1].
"""

from __future__ import annotations

import math

import numpy as np

from assurance.scenes import props
from assurance.scenes.builder import L_BLOCK, L_DETAIL, L_LOT_PAINT, Builder
from assurance.scenes.geom import ellipse
from assurance.scenes.styles import pick
from assurance.scenes.world import Look
from el.classes.labels import CLASS_IDS

CLUTTER = CLASS_IDS["clutter"]


def ground_region(b: Builder, a0: float, a1: float, b0: float, b1: float, label: int, look: Look,
                  layer: int = L_BLOCK) -> None:
    """Cover the local rectangle with one ground region (label, look, drawing layer)."""
    b.world.add_region(b.rect(a0, a1, b0, b1), label, look, layer)


def blob_region(b: Builder, a: float, c: float, ra: float, rb: float, label: int, look: Look,
                layer: int = L_DETAIL) -> None:
    """An irregular patch (soil, dry grass, gravel, pond) around local (a, c)."""
    jit = 1 + 0.25 * np.convolve(b.rng.normal(0, 1, 20), np.ones(3) / 3, mode="same")
    poly_local = ellipse(a, c, ra, rb, float(b.rng.uniform(0, math.pi)), n=20, jitter=np.clip(jit, 0.5, 1.5))
    world = b.origin + poly_local[:, :1] * b.ea + poly_local[:, 1:] * b.eb
    b.world.add_region(world, label, look, layer)


def lawn_look(b: Builder) -> Look:
    """A grass look (plain or mown) from the palette."""
    pal = b.palette
    return Look(str(b.rng.choice(["grass", "grass_mown"], p=[0.6, 0.4])), pick(b.rng, pal.grass, 0.1, 0.03))


def paved_look(b: Builder) -> Look:
    """A paving look: pavers (sometimes with a random cell size), slabs, concrete or asphalt."""
    rng, pal = b.rng, b.palette
    kind = str(rng.choice(["pavers", "slabs", "concrete_slab", "asphalt"], p=[0.35, 0.3, 0.15, 0.2]))
    colours = pal.lot_asphalt if kind == "asphalt" else pal.paving
    look = Look(kind, pick(rng, colours, 0.1, 0.02))
    if kind == "pavers" and rng.random() < 0.5:
        s = float(rng.uniform(0.25, 0.8))
        look = Look(kind, look.rgb, cell=(s, s * float(rng.uniform(0.5, 1.0)), 0.44, 0.42))
    return look


def scatter_trees(b: Builder, a0: float, a1: float, b0: float, b1: float, per_100m2: float,
                  *, clustered: bool = False) -> None:
    """Plant trees at ``per_100m2`` (Poisson), optionally in clusters, where there is room."""
    rng = b.rng
    area = max(0.0, (a1 - a0) * (b1 - b0))
    n = int(rng.poisson(per_100m2 * area / 100))
    centres = [(rng.uniform(a0, a1), rng.uniform(b0, b1)) for _ in range(max(1, n // 6))] if clustered else []
    for _ in range(n):
        if centres:
            ca, cb = centres[int(rng.integers(len(centres)))]
            a, c = ca + rng.normal(0, 8), cb + rng.normal(0, 8)
            if not (a0 < a < a1 and b0 < c < b1):
                continue
        else:
            a, c = rng.uniform(a0, a1), rng.uniform(b0, b1)
        props.tree_at_local(b, a, c)


def scatter_bushes(b: Builder, a0: float, a1: float, b0: float, b1: float, per_100m2: float) -> None:
    """Scatter bushes at ``per_100m2`` (Poisson) where there is room."""
    rng = b.rng
    n = int(rng.poisson(per_100m2 * max(0.0, (a1 - a0) * (b1 - b0)) / 100))
    for _ in range(n):
        a, c = rng.uniform(a0 + 1, a1 - 1), rng.uniform(b0 + 1, b1 - 1)
        if b.free_local(a, c, 1.0):
            x, y = b.to_world(a, c)
            props.add_bush(b, x, y, float(rng.uniform(0.5, 1.6)))


def scatter_clutter(b: Builder, a0: float, a1: float, b0: float, b1: float, n: int, kinds: list[str]) -> None:
    """Try ``n`` pieces of street furniture of the given kinds, aligned with the street grid."""
    rng = b.rng
    for _ in range(n):
        a, c = rng.uniform(a0 + 1, a1 - 1), rng.uniform(b0 + 1, b1 - 1)
        if b.free_local(a, c, 2.0):
            x, y = b.to_world(a, c)
            props.add_clutter(b, x, y, b.phi + float(rng.choice([0, math.pi / 2])) + float(rng.normal(0, 0.05)),
                              str(rng.choice(kinds)))


def park_cars_rows(b: Builder, a0: float, a1: float, b0: float, b1: float, fill: float, *,
                   lines: bool = True) -> None:
    """Rows of parking bays (5 m deep, 2.5 m wide, 6 m aisles) with bay lines and static cars."""
    rng, w = b.rng, b.world
    paint = Look("paint", pick(rng, b.palette.paint, 0.05))
    marks: list[np.ndarray] = []
    along_a = (a1 - a0) >= (b1 - b0)
    s0, s1, t0, t1 = (a0, a1, b0, b1) if along_a else (b0, b1, a0, a1)
    t = t0 + 0.5
    row = 0
    while t + 5.0 <= t1 - 0.5:
        s = s0 + 1.0
        while s + 2.5 <= s1 - 1.0:
            if lines:
                line = (s, s + 0.12, t, t + 5.0)
                marks.append(b.rect(*line) if along_a else b.rect(line[2], line[3], line[0], line[1]))
            if rng.random() < fill:
                cs, ct = s + 1.25, t + 2.5 + rng.normal(0, 0.15)
                x, y = b.to_world(cs, ct) if along_a else b.to_world(ct, cs)
                heading = (b.phi + math.pi / 2 if along_a else b.phi) + (math.pi if rng.random() < 0.5 else 0)
                if b.free_world(x, y, 1.0):
                    props.add_car(b, x, y, heading + rng.normal(0, 0.03), moving=False,
                                  kind=str(rng.choice(["sedan", "hatch", "suv", "van"], p=[0.4, 0.3, 0.22, 0.08])))
            s += 2.5
        t += 5.0 + (6.0 if row % 2 == 0 else 0.0)
        row += 1
    if marks:
        w.add_region(marks, CLUTTER, paint, L_LOT_PAINT)
