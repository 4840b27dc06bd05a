"""City layout: a rotated street grid with lanes, markings, sidewalks, verges and street life.

The grid lives in a local frame (a, b) rotated by a random angle and shifted by a random offset,
so streets cross the image at any angle and the camera may look at any part of a block. Roads
run along a ("horizontal", full length) and along b ("vertical", one segment per row of blocks,
some dropped so that blocks merge). Block contents are filled by ``assurance.scenes.blocks``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from assurance.scenes import props
from assurance.scenes.blocks import fill_block
from assurance.scenes.builder import L_BASE, L_CURB, L_MARKING, L_PATCH, L_ROAD, L_SIDEWALK, L_VERGE, Builder
from assurance.scenes.geom import ellipse
from assurance.scenes.styles import pick
from assurance.scenes.world import Look
from el.classes.labels import CLASS_IDS

ROAD = CLASS_IDS["road"]
CLUTTER = CLASS_IDS["clutter"]
LOW_VEG = CLASS_IDS["low_vegetation"]

PARKING_W = 2.3


@dataclass
class Road:
    """One street: carriageway centred on ``c`` (local coordinate across it), lanes, parking, sidewalks."""

    horizontal: bool
    c: float
    lanes: int
    lane_w: float
    park_lo: bool
    park_hi: bool
    sw_lo: float
    sw_hi: float
    verge_lo: float
    verge_hi: float
    look: Look
    paint: Look
    centre_solid: bool

    @property
    def width(self) -> float:
        return self.lanes * self.lane_w + PARKING_W * (self.park_lo + self.park_hi)

    @property
    def edge_lo(self) -> float:
        return self.c - self.width / 2

    @property
    def edge_hi(self) -> float:
        return self.c + self.width / 2

    @property
    def outer_lo(self) -> float:
        return self.edge_lo - self.verge_lo - self.sw_lo

    @property
    def outer_hi(self) -> float:
        return self.edge_hi + self.verge_hi + self.sw_hi

    @property
    def lanes_lo(self) -> float:
        return self.edge_lo + PARKING_W * self.park_lo

    @property
    def lanes_hi(self) -> float:
        return self.edge_hi - PARKING_W * self.park_hi

    @property
    def centre_line(self) -> float:
        return (self.lanes_lo + self.lanes_hi) / 2


# -- the street grid ------------------------------------------------------------------------------
def _road_spec(b: Builder, horizontal: bool) -> Road:
    st, rng, pal = b.style, b.rng, b.palette
    lanes = int(rng.choice(list(st.lanes), p=np.array(list(st.lanes.values())) / sum(st.lanes.values())))
    lane_w = float(rng.uniform(*st.lane_width))
    park_lo = bool(rng.random() < st.parking_lane_prob)
    park_hi = bool(rng.random() < st.parking_lane_prob)
    sw = float(rng.uniform(*st.sidewalk_width))
    verge = float(rng.uniform(1.5, 3.5)) if rng.random() < st.verge_prob else 0.0
    asphalt = pick(rng, pal.asphalt, 0.08, 0.015)
    material = "asphalt" if rng.random() < 0.7 else ("asphalt_worn" if rng.random() < 0.7 else "concrete_slab")
    if material == "concrete_slab":
        asphalt = pick(rng, pal.sidewalk, 0.06, 0.01)
    fade = float(rng.uniform(0.35, 1.0))
    paint_rgb = tuple(float(fade * p + (1 - fade) * a) for p, a in zip(pick(rng, pal.paint, 0.03), asphalt,
                                                                       strict=True))
    return Road(horizontal, 0.0, lanes, lane_w, park_lo, park_hi, sw, sw, verge, verge,
                Look(material, asphalt), Look("paint", paint_rgb), bool(rng.random() < 0.3))


def _place_roads(b: Builder, horizontal: bool) -> list[Road]:
    lo, hi = (b.bmin, b.bmax) if horizontal else (b.amin, b.amax)
    roads: list[Road] = []
    pos = lo - float(b.rng.uniform(5, b.style.block_size[1]))
    while True:
        r = _road_spec(b, horizontal)
        if roads:
            pos = roads[-1].outer_hi + float(b.rng.uniform(*b.style.block_size)) + (r.c - r.outer_lo)
        r.c = pos
        roads.append(r)
        if r.outer_lo > hi + 20:
            break
    return roads


def build_city(b: Builder) -> None:
    """Lay out the street grid, fill every block in the domain, then add street life."""
    h_roads = _place_roads(b, True)
    v_roads = _place_roads(b, False)
    rng, st = b.rng, b.style
    a_lo, a_hi = b.amin - 60, b.amax + 60
    # vertical segments per row: present[row][k]
    present = [[(k in (0, len(v_roads) - 1)) or rng.random() >= st.drop_road_prob for k in range(len(v_roads))]
               for _ in range(len(h_roads) - 1)]
    base = pick(rng, b.palette.grass + b.palette.soil, 0.1)
    b.world.add_region(b.rect(a_lo - 2000, a_hi + 2000, b.bmin - 2000, b.bmax + 2000), CLUTTER,
                       Look("soil", base), L_BASE)
    # blocks
    for row in range(len(h_roads) - 1):
        b0, b1 = h_roads[row].outer_hi, h_roads[row + 1].outer_lo
        ks = [k for k in range(len(v_roads)) if present[row][k]]
        for k0, k1 in zip(ks[:-1], ks[1:], strict=True):
            a0, a1 = v_roads[k0].outer_hi, v_roads[k1].outer_lo
            if a1 - a0 < 4 or b1 - b0 < 4 or not b.in_domain(a0, a1, b0, b1, margin=5):
                continue
            fill_block(b, a0, a1, b0, b1)
    # streets: horizontal roads run through; vertical ones per row
    for li, road in enumerate(h_roads):
        if not b.in_domain(a_lo, a_hi, road.outer_lo, road.outer_hi):
            continue
        crossings = sorted({k for row in (li - 1, li) if 0 <= row < len(present)
                            for k in range(len(v_roads)) if present[row][k]})
        zones = [(v_roads[k].outer_lo, v_roads[k].outer_hi) for k in crossings]
        _street(b, road, a_lo, a_hi, zones)
    for row in range(len(h_roads) - 1):
        s0, s1 = h_roads[row].edge_hi, h_roads[row + 1].edge_lo
        zones = [(h_roads[row].edge_hi - 50, h_roads[row].outer_hi), (h_roads[row + 1].outer_lo, s1 + 50)]
        for k, road in enumerate(v_roads):
            if present[row][k] and b.in_domain(road.outer_lo, road.outer_hi, s0, s1):
                _street(b, road, s0, s1, zones)


# -- one street -------------------------------------------------------------------------------
def _strip(b: Builder, road: Road, s0: float, s1: float, t0: float, t1: float) -> np.ndarray:
    """World polygon of the road-frame rectangle [s0, s1] along x [t0, t1] across."""
    if road.horizontal:
        return b.rect(s0, s1, t0, t1)
    return b.rect(t0, t1, s0, s1)


def _point(b: Builder, road: Road, s: float, t: float) -> tuple[float, float]:
    return b.to_world(s, t) if road.horizontal else b.to_world(t, s)


def _heading(b: Builder, road: Road) -> float:
    return b.phi if road.horizontal else b.phi + math.pi / 2


def _pieces(s0: float, s1: float, zones: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Intervals of [s0, s1] outside the given zones (intersections)."""
    out, cur = [], s0
    for z0, z1 in sorted(zones):
        if z1 <= cur:
            continue
        if z0 > cur:
            out.append((cur, min(z0, s1)))
        cur = max(cur, z1)
        if cur >= s1:
            break
    if cur < s1:
        out.append((cur, s1))
    return [(a, c) for a, c in out if c - a > 1.0]


def _street(b: Builder, road: Road, s0: float, s1: float, zones: list[tuple[float, float]]) -> None:
    """Sidewalks, curbs, verges, carriageway, markings, cars, trees, furniture and people of a street."""
    rng, pal = b.rng, b.palette
    w = b.world
    sw_look = Look(str(rng.choice(["slabs", "pavers", "curb"], p=[0.5, 0.3, 0.2])), pick(rng, pal.sidewalk, 0.08))
    w.add_region(_strip(b, road, s0, s1, road.outer_lo, road.outer_hi), CLUTTER, sw_look, L_SIDEWALK)
    w.add_region(_strip(b, road, s0, s1, road.edge_lo, road.edge_hi), ROAD, road.look, L_ROAD)
    pieces = _pieces(s0, s1, zones)
    curb = Look("curb", pick(rng, pal.sidewalk, 0.05))
    verge_look = Look("grass", pick(rng, pal.grass + pal.dry_grass, 0.1))
    heading = _heading(b, road)
    marks: list[np.ndarray] = []
    for p0, p1 in pieces:
        for side in (-1, 1):
            edge = road.edge_lo if side < 0 else road.edge_hi
            verge = road.verge_lo if side < 0 else road.verge_hi
            w.add_region(_strip(b, road, p0, p1, *sorted((edge, edge + side * 0.25))), CLUTTER, curb, L_CURB)
            if verge > 0:
                t_a, t_b = sorted((edge + side * 0.25, edge + side * verge))
                w.add_region(_strip(b, road, p0 + 0.5, p1 - 0.5, t_a, t_b), LOW_VEG, verge_look, L_VERGE)
        _markings(b, road, p0, p1, marks, first=p0 <= s0 + 1e-6, last=p1 >= s1 - 1e-6)
        _patches(b, road, p0, p1)
        _parked_cars(b, road, p0, p1, heading)
        _moving_cars(b, road, p0, p1, heading)
        _street_side(b, road, p0, p1, heading)
    if marks:
        w.add_region(marks, ROAD, road.paint, L_MARKING, footprint=False)


def _markings(b: Builder, road: Road, p0: float, p1: float, out: list[np.ndarray], *, first: bool,
              last: bool) -> None:
    """Centre and lane lines, parking edge lines, zebra crossings and stop lines of one piece."""
    rng = b.rng
    m0 = p0 + (0.0 if first else 4.5)
    m1 = p1 - (0.0 if last else 4.5)
    if m1 - m0 < 3:
        return
    lw = 0.15
    dash, gap = float(rng.uniform(2.5, 4.0)), float(rng.uniform(4.0, 7.0))
    phase = float(rng.uniform(0, dash + gap))

    def dashed(t: float) -> None:
        s = m0 - phase
        while s < m1:
            a, c = max(s, m0), min(s + dash, m1)
            if c - a > 0.3:
                out.append(_strip(b, road, a, c, t - lw / 2, t + lw / 2))
            s += dash + gap

    cl = road.centre_line
    if road.lanes >= 2:
        if road.centre_solid or road.lanes >= 4:
            out.append(_strip(b, road, m0, m1, cl - lw / 2, cl + lw / 2))
            if road.lanes >= 4 and rng.random() < 0.5:
                out.append(_strip(b, road, m0, m1, cl + 0.3 - lw / 2, cl + 0.3 + lw / 2))
        else:
            dashed(cl)
    for k in range(1, road.lanes // 2):
        dashed(cl + k * road.lane_w)
        dashed(cl - k * road.lane_w)
    if rng.random() < 0.6:
        for t in (road.lanes_lo, road.lanes_hi):
            out.append(_strip(b, road, m0, m1, t - 0.06, t + 0.06))
    # zebra crossings and stop lines at the intersection ends
    for end, sign in ((p0, 1), (p1, -1)):
        if (end == p0 and first) or (end == p1 and last):
            continue
        if rng.random() < 0.55:
            s_a, s_b = sorted((end + sign * 0.8, end + sign * 3.8))
            t = road.edge_lo + 0.3
            while t + 0.5 < road.edge_hi - 0.2:
                out.append(_strip(b, road, s_a, s_b, t, t + 0.5))
                t += 1.0
        if rng.random() < 0.5:
            s_a, s_b = sorted((end + sign * 4.3, end + sign * 4.7))
            if sign > 0:
                out.append(_strip(b, road, s_a, s_b, cl, road.lanes_hi))
            else:
                out.append(_strip(b, road, s_a, s_b, road.lanes_lo, cl))


def _patches(b: Builder, road: Road, p0: float, p1: float) -> None:
    """Road wear, all still road: repaired patches, darker tyre tracks, sealed cracks and manholes."""
    rng, w = b.rng, b.world
    base = road.look.rgb

    def tone(k: float) -> tuple[float, float, float]:
        return tuple(float(np.clip(c * k, 0, 1)) for c in base)  # type: ignore[return-value]

    for _ in range(int(rng.poisson((p1 - p0) / 60))):
        ln = float(rng.uniform(1.5, 12))
        s = float(rng.uniform(p0, max(p0, p1 - ln)))
        t0 = float(rng.uniform(road.edge_lo, road.edge_hi - 1))
        t1 = min(road.edge_hi, t0 + float(rng.uniform(0.8, 3.5)))
        w.add_region(_strip(b, road, s, s + ln, t0, t1), ROAD, Look("asphalt", tone(float(rng.uniform(0.8, 1.15)))),
                     L_PATCH, footprint=False)
    if road.look.material != "concrete_slab" and rng.random() < 0.7:
        tracks = []
        for lane in range(road.lanes):
            tc = road.lanes_lo + (lane + 0.5) * road.lane_w
            for off in (-0.85, 0.85):
                t = tc + off + float(rng.normal(0, 0.08))
                tracks.append(_strip(b, road, p0, p1, t - 0.3, t + 0.3))
        w.add_region(tracks, ROAD, Look("asphalt", tone(float(rng.uniform(0.88, 0.95)))), L_PATCH, footprint=False)
    cracks = []
    for _ in range(int(rng.poisson((p1 - p0) / 25))):
        s, t = float(rng.uniform(p0, p1)), float(rng.uniform(road.edge_lo + 0.3, road.edge_hi - 0.3))
        ang = float(rng.uniform(0, 2 * math.pi))
        for _ in range(int(rng.integers(3, 12))):
            ang += float(rng.normal(0, 0.5))
            ln = float(rng.uniform(0.3, 1.2))
            s2, t2 = s + ln * math.cos(ang), t + ln * math.sin(ang)
            if not (p0 < s2 < p1 and road.edge_lo < t2 < road.edge_hi):
                break
            cracks.append(_segment(b, road, s, t, s2, t2, float(rng.uniform(0.03, 0.07))))
            s, t = s2, t2
    if cracks:
        w.add_region(cracks, ROAD, Look("asphalt", tone(0.55)), L_PATCH, footprint=False)
    holes = []
    for _ in range(int(rng.poisson((p1 - p0) / 45))):
        x, y = _point(b, road, float(rng.uniform(p0, p1)), float(rng.uniform(road.lanes_lo + 1, road.lanes_hi - 1)))
        holes.append(ellipse(x, y, 0.33, 0.33, 0.0, n=12))
    if holes:
        w.add_region(holes, ROAD, Look("metal", tone(0.7)), L_PATCH, footprint=False)


def _segment(b: Builder, road: Road, s0: float, t0: float, s1: float, t1: float, width: float) -> np.ndarray:
    """A thin quad from (s0, t0) to (s1, t1) in the road frame, in world coordinates."""
    p = np.array(_point(b, road, s0, t0))
    q = np.array(_point(b, road, s1, t1))
    d = q - p
    n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-9) * (width / 2)
    return np.array([p - n, q - n, q + n, p + n])


def _parked_cars(b: Builder, road: Road, p0: float, p1: float, heading: float) -> None:
    rng, st = b.rng, b.style
    for side, present in ((-1, road.park_lo), (1, road.park_hi)):
        if not present:
            continue
        t = (road.edge_lo + PARKING_W / 2) if side < 0 else (road.edge_hi - PARKING_W / 2)
        s = p0 + 2.0 + float(rng.uniform(0, 3))
        while s < p1 - 4.0:
            slot = float(rng.uniform(5.3, 7.0))
            if rng.random() < st.parked_fill:
                x, y = _point(b, road, s + slot / 2, t + float(rng.normal(0, 0.12)))
                flip = math.pi if rng.random() < 0.5 else 0.0
                props.add_car(b, x, y, heading + flip + float(rng.normal(0, 0.02)), moving=False,
                              kind=str(rng.choice(["sedan", "hatch", "suv", "van"], p=[0.4, 0.3, 0.22, 0.08])))
            s += slot


def _moving_cars(b: Builder, road: Road, p0: float, p1: float, heading: float) -> None:
    rng, st = b.rng, b.style
    for lane in range(road.lanes):
        t = road.lanes_lo + (lane + 0.5) * road.lane_w
        forward = t > road.centre_line
        n = int(rng.poisson(st.moving_per_100m * (p1 - p0) / 100))
        for _ in range(n):
            s = float(rng.uniform(p0 + 3, p1 - 3)) if p1 - p0 > 6 else (p0 + p1) / 2
            x, y = _point(b, road, s, t + float(rng.normal(0, 0.2)))
            if not b.free_world(x, y, 2.6):
                continue
            moving = rng.random() > 0.08  # a few stopped cars in the lanes (queues): static
            props.add_car(b, x, y, heading + (0.0 if forward else math.pi) + float(rng.normal(0, 0.015)),
                          moving=moving)


def _verge_cars(b: Builder, road: Road, p0: float, p1: float, t: float, heading: float) -> None:
    """Static cars parked on a grass verge (a look-alike hazard: a car on what reads as lawn)."""
    rng = b.rng
    s = p0 + float(rng.uniform(2, 12))
    while s < p1 - 3:
        if rng.random() < 0.45:
            x, y = _point(b, road, s, t + float(rng.normal(0, 0.15)))
            if b.free_world(x, y, 1.0):
                props.add_car(b, x, y, heading + float(rng.normal(0, 0.04)) + (math.pi if rng.random() < 0.5 else 0),
                              moving=False, kind=str(rng.choice(["sedan", "hatch", "suv"])))
        s += float(rng.uniform(5.5, 9.0))


def _street_side(b: Builder, road: Road, p0: float, p1: float, heading: float) -> None:
    """Street trees (overhanging the road), lamps, benches, bins, pits and people on both sidewalks."""
    rng, st, pal, w = b.rng, b.style, b.palette, b.world
    for side in (-1, 1):
        edge = road.edge_lo if side < 0 else road.edge_hi
        verge = road.verge_lo if side < 0 else road.verge_hi
        sw = road.sw_lo if side < 0 else road.sw_hi
        if rng.random() < st.street_tree_prob:
            spacing = float(rng.uniform(*st.street_tree_spacing))
            radius_base = float(rng.uniform(*st.tree_size))
            colour = pick(rng, pal.tree, 0.1, 0.02)
            t = edge + side * (verge / 2 if verge > 0 else float(rng.uniform(0.8, 1.3)))
            s = p0 + float(rng.uniform(1.0, spacing))
            while s < p1 - 1.0:
                if rng.random() < 0.88:
                    x, y = _point(b, road, s + float(rng.normal(0, 0.3)), t)
                    r = radius_base * float(rng.uniform(0.75, 1.2))
                    if verge <= 0 and rng.random() < 0.7:
                        pit = _strip(b, road, s - 0.7, s + 0.7, *sorted((t - 0.7, t + 0.7)))
                        w.add_region(pit, CLUTTER, Look("soil", pick(rng, pal.soil, 0.1)), L_VERGE)
                    if b.free_world(x, y, 0.6) and b.free_world(x, y, 0.7 * r, buildings_only=True):
                        props.add_tree(b, x, y, r, colour=pick(rng, (colour,), 0.08, 0.02))
                s += spacing
        if verge >= 2.0 and rng.random() < st.verge_parking_prob:
            _verge_cars(b, road, p0, p1, edge + side * (verge / 2 + 0.2), heading)
        if rng.random() < 0.7:
            s = p0 + float(rng.uniform(3, 20))
            gap = float(rng.uniform(22, 35))
            t = edge + side * (verge + 0.5 if verge > 0 else 0.5)
            while s < p1 - 2:
                x, y = _point(b, road, s, t)
                if b.free_world(x, y, 0.5):
                    props.add_clutter(b, x, y, heading + (0 if side > 0 else math.pi), "lamp")
                s += gap
        t_in = edge + side * (verge + sw * 0.75)
        n_furn = int(rng.poisson((p1 - p0) / 45))
        for _ in range(n_furn):
            s = float(rng.uniform(p0 + 1, p1 - 1))
            x, y = _point(b, road, s, t_in)
            if b.free_world(x, y, 1.2):
                kind = str(rng.choice(["bench", "bin", "bollard", "kiosk", "dumpster"],
                                      p=[0.35, 0.3, 0.15, 0.08, 0.12]))
                props.add_clutter(b, x, y, heading, kind)
        area = (p1 - p0) * sw
        n_groups = int(rng.poisson(st.people_per_100m2 * area / 100 * 1.5))
        for _ in range(n_groups):
            s = float(rng.uniform(p0, p1))
            t = edge + side * (verge + float(rng.uniform(0.3, max(0.4, sw - 0.3))))
            x, y = _point(b, road, s, t)
            props.add_people(b, x, y, int(rng.integers(1, 4)), spread=0.5)
    # people crossing at the ends of the piece
    if rng.random() < 0.25:
        s = p0 + 2.0 if rng.random() < 0.5 else p1 - 2.0
        t = float(rng.uniform(road.edge_lo + 0.5, road.edge_hi - 0.5))
        x, y = _point(b, road, s, t)
        props.add_people(b, x, y, int(rng.integers(1, 4)), spread=0.6)
