"""Detached-house blocks: two rows of lots, each with a house, driveway and car, hedges and a back yard.

A block filler of :mod:`assurance.scenes.blocks` (kept apart so that each module stays small).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from assurance.scenes import props
from assurance.scenes.builder import L_DETAIL, L_DETAIL2, Builder
from assurance.scenes.ground import blob_region, ground_region, lawn_look, paved_look, scatter_bushes
from assurance.scenes.styles import pick
from assurance.scenes.world import Look
from el.classes.labels import CLASS_IDS

CLUTTER = CLASS_IDS["clutter"]
LOW_VEG = CLASS_IDS["low_vegetation"]


def houses(b: Builder, a0: float, a1: float, b0: float, b1: float) -> None:
    """Two rows of lots back to back: house, lawn, hedges, driveway with a car, trees, sheds, pools."""
    rng = b.rng
    ground_region(b, a0, a1, b0, b1, LOW_VEG, lawn_look(b))
    along_a = (a1 - a0) >= (b1 - b0)
    s0, s1, t0, t1 = (a0, a1, b0, b1) if along_a else (b0, b1, a0, a1)
    rows = [(t0, (t0 + t1) / 2, 1), ((t0 + t1) / 2, t1, -1)] if t1 - t0 > 30 else [(t0, t1, 1)]
    for r0, r1, facing in rows:
        s = s0
        while s < s1 - 8:
            lot = float(rng.uniform(11, 20))
            if s1 - (s + lot) < 10:
                lot = s1 - s
            _house_lot(b, s, s + lot, r0, r1, facing, along_a)
            s += lot


def _house_lot(b: Builder, s0: float, s1: float, t0: float, t1: float, facing: int, along_a: bool) -> None:
    """One lot [s0, s1] along the street x [t0, t1] deep, its front on the ``facing`` side: house, driveway, yard."""
    rng, st, w = b.rng, b.style, b.world

    def loc(s: float, t: float) -> tuple[float, float]:
        return (s, t) if along_a else (t, s)

    def lrect(sa: float, sb: float, ta: float, tb: float) -> np.ndarray:
        (a_0, b_0), (a_1, b_1) = loc(sa, ta), loc(sb, tb)
        return b.rect(min(a_0, a_1), max(a_0, a_1), min(b_0, b_1), max(b_0, b_1))

    depth = t1 - t0
    front = t0 if facing > 0 else t1
    setback = float(rng.uniform(2.5, 7))
    hw = float(min(rng.uniform(8, 14), s1 - s0 - 4))
    hd = float(min(rng.uniform(8, 12), depth - setback - 4))
    if hw < 5 or hd < 5:
        return
    hs = float(rng.uniform(s0 + 2, s1 - 2 - hw))
    ht = front + facing * (setback + hd / 2)
    # driveway and car
    drive_s = hs + hw + 0.5 if s1 - (hs + hw) > 4 else hs - 3.5
    if s0 + 0.5 < drive_s < s1 - 3.5:
        drive = lrect(drive_s, drive_s + 3.0, *sorted((front, front + facing * (setback + hd))))
        w.add_region(drive, CLUTTER, paved_look(b), L_DETAIL)
        if rng.random() < 0.55:
            ca, cb = loc(drive_s + 1.5, front + facing * float(rng.uniform(2.8, setback + 1)))
            x, y = b.to_world(ca, cb)
            heading = (b.phi + math.pi / 2 if along_a else b.phi) + (0 if facing > 0 else math.pi)
            props.add_car(b, x, y, heading, moving=False, kind=str(rng.choice(["sedan", "hatch", "suv"])))
    if rng.random() < 0.35:  # terrace / yard paving behind the house
        tt = front + facing * (setback + hd)
        w.add_region(lrect(hs, hs + hw, *sorted((tt, tt + facing * float(rng.uniform(2, 4))))), CLUTTER,
                     paved_look(b), L_DETAIL)
    ca, cb = loc(hs + hw / 2, ht)
    x, y = b.to_world(ca, cb)
    h = float(np.clip(rng.uniform(*st.building_height), 3.5, 12))
    pitched = rng.random() < st.pitched_prob
    ang = b.phi if along_a else b.phi + math.pi / 2
    bw, bl = hw, hd
    if pitched and rng.random() < 0.35:
        bw, bl, ang = hd, hw, ang + math.pi / 2
    props.add_building(b, x, y, bw, bl, ang, h,
                       style=props.BuildingStyle(pitched=pitched, equipment=rng.random() < 0.3))
    # hedges on the lot sides, trees and extras in the back
    if rng.random() < 0.2:
        side_len = min(depth - 2, setback + hd + float(rng.uniform(0, 8)))
        for s_edge in (s0 + 0.5, s1 - 0.5):
            ca, cb = loc(s_edge, front + facing * side_len / 2)
            x, y = b.to_world(ca, cb)
            props.add_hedge(b, x, y, side_len, (b.phi + math.pi / 2) if along_a else b.phi)
    if rng.random() < 0.3:
        ca, cb = loc((s0 + s1) / 2, front + facing * 0.6)
        x, y = b.to_world(ca, cb)
        props.add_hedge(b, x, y, s1 - s0 - 4, b.phi if along_a else b.phi + math.pi / 2)
    back0 = front + facing * (setback + hd + 1)
    back1 = t1 if facing > 0 else t0
    ba, bb = sorted((back0, back1))
    if bb - ba > 3:
        _back_yard(b, loc, s0, s1, ba, bb, ang)
    if rng.random() < 0.15:
        ca, cb = loc(float(rng.uniform(s0 + 1, s1 - 1)), front + facing * float(rng.uniform(0.5, setback)))
        x, y = b.to_world(ca, cb)
        props.add_people(b, x, y, int(rng.integers(1, 3)), spread=0.6)


def _back_yard(b: Builder, loc: Callable[[float, float], tuple[float, float]], s0: float, s1: float, ba: float,
               bb: float, ang: float) -> None:
    """The back of a house lot, [s0, s1] x [ba, bb] in lot coordinates (``loc`` maps them to the block's):
    trees, then a pool or a shed (at angle ``ang``), a patch of soil and bushes."""
    rng, pal, w = b.rng, b.palette, b.world
    for _ in range(int(rng.integers(0, 4))):
        ca, cb = loc(float(rng.uniform(s0 + 1, s1 - 1)), float(rng.uniform(ba, bb)))
        props.tree_at_local(b, ca, cb)
    if rng.random() < 0.2 and bb - ba > 7:
        ca, cb = loc(float(rng.uniform(s0 + 3, s1 - 3)), (ba + bb) / 2)
        if b.free_local(ca, cb, 3):
            pool = Look("water", pick(rng, ((0.35, 0.60, 0.70), (0.30, 0.52, 0.62)), 0.08))
            w.add_region(b.rect(ca - 2.5, ca + 2.5, cb - 1.8, cb + 1.8), CLUTTER, pool, L_DETAIL2)
            b.occupy_local(ca - 2.5, ca + 2.5, cb - 1.8, cb + 1.8)
    elif rng.random() < 0.3:
        ca, cb = loc(float(rng.uniform(s0 + 2, s1 - 2)), (ba + bb) / 2)
        if b.free_local(ca, cb, 2.5):
            x, y = b.to_world(ca, cb)
            props.add_clutter(b, x, y, ang, "shed")
    if rng.random() < 0.4:
        ca, cb = loc(float(rng.uniform(s0 + 2, s1 - 2)), (ba + bb) / 2)
        blob_region(b, ca, cb, float(rng.uniform(1.5, 4)), float(rng.uniform(1, 3)), CLUTTER,
                    Look("soil", pick(rng, pal.soil, 0.1)), L_DETAIL)
    (qa0, qb0), (qa1, qb1) = loc(s0, ba), loc(s1, bb)
    scatter_bushes(b, min(qa0, qa1), max(qa0, qa1), min(qb0, qb1), max(qb0, qb1), 0.6)
