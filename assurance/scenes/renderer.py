"""Render a world through a pinhole camera: exact label map and a shaded, anti-aliased image.

1. Ground regions are projected (the ground plane maps to the image by a homography, so straight
   edges stay straight) and filled in layer order into a face-id map.
2. Solids (boxes, gabled houses) and crown blobs are culled, put in occlusion order
   (``assurance.scenes.order``) and their visible faces filled far to near.
3. Shadows: ground shadow polygons, roof shadows, one sun ray per object for the rest.
4. Labels are read from the face table (exact, never blended); the image is shaded per pixel
   (``assurance.scenes.shade``), which textures every surface in its own metric coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from assurance.scenes.faces import CANOPY, GROUND, HORIZONTAL, PLANAR, FaceLight, FaceTable
from assurance.scenes.geom import clip_to_box, convex_hull
from assurance.scenes.order import draw_order
from assurance.scenes.shade import ShadeInputs, shade
from assurance.scenes.shadows import Casters, project_to_plane, unit_sphere
from assurance.scenes.view import visible_ground
from assurance.scenes.world import World
from el.classes.labels import CLASS_IDS
from el.geometry.camera import CameraGeometry

SHIFT = 4  # fixed-point bits for OpenCV polygon filling
ONE = 1 << SHIFT
TREE = CLASS_IDS["tree"]
BUILDING = CLASS_IDS["building"]

# face templates over the 10 block vertices: 0-3 bottom, 4-7 top, 8/9 ridge ends (-u / +u)
BOX_FACES = ([0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7], [4, 5, 6, 7])
GABLE_FACES = ([0, 1, 5, 4], [1, 2, 6, 9, 5], [2, 3, 7, 6], [3, 0, 4, 8, 7], [4, 5, 9, 8], [6, 7, 8, 9])
SPHERE = unit_sphere()
CIRCLE = np.stack([np.cos(np.linspace(0, 2 * np.pi, 12, endpoint=False)),
                   np.sin(np.linspace(0, 2 * np.pi, 12, endpoint=False))], axis=1)


@dataclass
class Rendered:
    """A rendered view: RGB image (H, W, 3) uint8, class ids (H, W) uint8, and the number of
    pixels no modelled surface covered (0 when the world covers the whole view)."""

    image: np.ndarray
    labels: np.ndarray
    void: int = 0


class _Camera:
    """Projection helpers for one geometry (vectorised)."""

    def __init__(self, g: CameraGeometry) -> None:
        self.g = g
        self.W, self.H = g.width, g.height
        self.Hc = g.pose.height_m
        self.st, self.ct = math.sin(g.theta), math.cos(g.theta)
        self.f = g.f_px
        self.C = np.array([0.0, 0.0, self.Hc])

    def project(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(..., 3) world points -> (..., 2) pixel coordinates and (...,) depth."""
        col, row = self.g.ground_to_pixel(pts[..., 0], pts[..., 1], pts[..., 2])
        depth = self.g.camera_to_point_distance(pts[..., 0], pts[..., 1], pts[..., 2])
        return np.stack([col, row], axis=-1), depth

    def linear_form(self, vec: np.ndarray) -> np.ndarray:
        """Coefficients (..., 3) of vec . D(h, v) where D is the pixel ray direction."""
        st, ct, f = self.st, self.ct, self.f
        return np.stack([vec[..., 0], -vec[..., 1] * st - vec[..., 2] * ct,
                         f * (vec[..., 1] * ct - vec[..., 2] * st)], axis=-1)


def fill_polygon(img: np.ndarray, pts: np.ndarray, value: int, *, convex: bool = False) -> None:
    """Fill a polygon given in float pixel coordinates (pixel centres at integers).

    Polygons crossing the image border are clipped first: OpenCV's sub-pixel filling otherwise
    smears slivers that lie outside the image onto the border column.
    """
    h, w = img.shape[:2]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    if hi[0] < -0.5 or hi[1] < -0.5 or lo[0] > w - 0.5 or lo[1] > h - 0.5:
        return
    if lo[0] < -0.5 or lo[1] < -0.5 or hi[0] > w - 0.5 or hi[1] > h - 0.5:
        pts = clip_to_box(pts, -0.5, w - 0.5, -0.5, h - 0.5)
        if len(pts) < 3:
            return
    fixed = np.round(pts * ONE).astype(np.int32)
    if convex:
        cv2.fillConvexPoly(img, fixed, value, cv2.LINE_8, SHIFT)
    else:
        cv2.fillPoly(img, [fixed], value, cv2.LINE_8, SHIFT)


def render(world: World, geometry: CameraGeometry) -> Rendered:
    """Draw ``world`` as seen by ``geometry``: labels exact, image shaded and anti-aliased."""
    cam = _Camera(geometry)
    face_map = np.zeros((cam.H, cam.W), dtype=np.int32)
    table = FaceTable()
    vis = visible_ground(geometry)
    y_front = -cam.Hc * cam.st / max(cam.ct, 1e-3) + 1.0  # ground points with larger y lie in front
    clip = (float(vis[:, 0].min() - 5), float(vis[:, 0].max() + 5), float(max(vis[:, 1].min() - 5, y_front)),
            float(vis[:, 1].max() + 5))
    sun = world.sun.vector()
    _draw_ground(world, cam, face_map, table, clip, sun)
    casters = Casters.from_world(world, clip, crown_labels=(TREE,))
    roofs = _draw_solids(world, cam, face_map, table, sun, casters)
    hard, soft, ao = _ground_shadows(world, cam, clip, sun)
    roof_mask = _roof_shadows(world, cam, face_map, roofs, sun, casters)
    faces = table.arrays()
    labels = faces.label[face_map]
    image = shade(face_map, faces, ShadeInputs(geometry=geometry, world=world, sun=sun, hard=hard, soft=soft,
                                               roof=roof_mask, ao=ao))
    return Rendered(image=image, labels=labels, void=int(np.count_nonzero(face_map == 0)))


# -- ground ----------------------------------------------------------------------------------------
def _draw_ground(world: World, cam: _Camera, face_map: np.ndarray, table: FaceTable,
                 clip: tuple[float, float, float, float], sun: np.ndarray) -> None:
    order = sorted(range(len(world.regions)), key=lambda i: world.regions[i].layer)
    lam = float(max(sun[2], 0.0))
    for i in order:
        reg = world.regions[i]
        polys = []
        for p in reg.polygons:
            c = clip_to_box(p, *clip)
            if len(c) >= 3:
                polys.append(c)
        if not polys:
            continue
        fid = table.add(GROUND, reg.label, reg.look, light=FaceLight(lambert=lam))
        for c in polys:
            pix, _ = cam.project(np.concatenate([c, np.zeros((len(c), 1))], axis=1))
            fill_polygon(face_map, pix, int(fid))


# -- solids ------------------------------------------------------------------------------------------
def _block_arrays(blocks: list) -> dict[str, np.ndarray]:
    out = {k: np.array([getattr(x, k) for x in blocks], dtype=np.float64)
           for k in ("cx", "cy", "w", "l", "angle", "z0", "h", "gable")}
    taper = np.array([x.taper for x in blocks], dtype=np.float64).reshape(-1, 2)
    out["tw"], out["tl"] = taper[:, 0], taper[:, 1]
    return out


def _block_vertices(a: dict[str, np.ndarray]) -> np.ndarray:
    """Vertices (B, 10, 3) of every block: 0-3 base, 4-7 top (tapered), 8/9 ridge ends."""
    c, s = np.cos(a["angle"]), np.sin(a["angle"])
    zero = np.zeros_like(c)
    u = np.stack([c, s, zero], axis=1)
    v = np.stack([-s, c, zero], axis=1)
    hu = u * (a["w"] / 2)[:, None]
    hv = v * (a["l"] / 2)[:, None]
    ctr = np.stack([a["cx"], a["cy"], a["z0"]], axis=1)
    bottom = np.stack([ctr - hu - hv, ctr + hu - hv, ctr + hu + hv, ctr - hu + hv], axis=1)
    tu, tv = hu * a["tw"][:, None], hv * a["tl"][:, None]
    ctop = ctr + np.stack([zero, zero, a["h"]], axis=1)
    top = np.stack([ctop - tu - tv, ctop + tu - tv, ctop + tu + tv, ctop - tu + tv], axis=1)
    ridge = np.stack([(top[:, 0] + top[:, 3]) / 2, (top[:, 1] + top[:, 2]) / 2], axis=1)
    ridge[..., 2] += a["gable"][:, None]
    return np.concatenate([bottom, top, ridge], axis=1)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-12)


def _face_frames(verts: np.ndarray, templates: tuple[list[int], ...]
                 ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per face template: outward unit normal, origin, in-plane axes e1 (along the first edge) and e2 (upward)."""
    centre = verts[:, :8].mean(axis=1)
    out = []
    for tmpl in templates:
        p = verts[:, tmpl]
        q = np.roll(p, -1, axis=1)
        n = np.stack([((p[..., 1] - q[..., 1]) * (p[..., 2] + q[..., 2])).sum(axis=1),
                      ((p[..., 2] - q[..., 2]) * (p[..., 0] + q[..., 0])).sum(axis=1),
                      ((p[..., 0] - q[..., 0]) * (p[..., 1] + q[..., 1])).sum(axis=1)], axis=1)
        n = _unit(n)
        outward = ((p.mean(axis=1) - centre) * n).sum(axis=1)
        n = np.where(outward[:, None] < 0, -n, n)
        e1 = _unit(p[:, 1] - p[:, 0])
        e2 = np.cross(n, e1)
        e2 = np.where(e2[:, 2:3] < 0, -e2, e2)
        out.append((n, p[:, 0], e1, e2))
    return out


def _draw_solids(world: World, cam: _Camera, face_map: np.ndarray, table: FaceTable, sun: np.ndarray,
                 casters: Casters) -> list[tuple[int, int]]:
    """Fill all visible faces of blocks and crowns in occlusion order; returns (face id, block) of flat roofs."""
    W, H = cam.W, cam.H
    objects: list[tuple[str, int]] = []
    fps, zmins, zmaxs, boxes, keys = [], [], [], [], []
    if world.blocks:
        verts = _block_vertices(_block_arrays(world.blocks))
        pix, depth = cam.project(verts)
        bb = np.concatenate([pix.min(axis=1), pix.max(axis=1)], axis=1)
        ok = (depth.min(axis=1) > 0.5) & (bb[:, 2] >= -1) & (bb[:, 0] <= W) & (bb[:, 3] >= -1) & (bb[:, 1] <= H)
        idx = np.flatnonzero(ok)
        offsets = (np.stack([idx * 7.31, idx * 3.17], axis=1) + world.seed * 0.37) % 200.0
        offsets_of = dict(zip(idx.tolist(), offsets.tolist(), strict=True))
        for i in idx.tolist():
            blk = world.blocks[i]
            objects.append(("block", i))
            fps.append(verts[i, :4, :2])
            zmins.append(blk.z0)
            zmaxs.append(blk.top_z)
            boxes.append(bb[i])
            keys.append(math.hypot(blk.cx, blk.cy))
        faces = {g: _face_data(cam, verts, GABLE_FACES if g else BOX_FACES, sun) for g in (False, True)}
    crown_data = _visible_crowns(world, cam)
    for ci, (_, _, lo, hi) in crown_data.items():
        bl = world.crowns[ci].blobs
        ring = (bl[:, None, :2] + CIRCLE[None] * bl[:, None, 3:4]).reshape(-1, 2)
        objects.append(("crown", ci))
        fps.append(convex_hull(ring))
        zmins.append(world.crowns[ci].bottom_z)
        zmaxs.append(world.crowns[ci].top_z)
        boxes.append(np.concatenate([lo, hi]))
        keys.append(math.hypot(*bl[:, :2].mean(axis=0)))
    if not objects:
        return []
    k = max(len(f) for f in fps)
    padded = np.array([np.concatenate([f, np.repeat(f[-1:], k - len(f), axis=0)]) for f in fps])
    order = draw_order(padded, np.array(zmins), np.array(zmaxs), np.array(boxes), np.array(keys))
    shadow_amount = _object_shadows(world, objects, casters, sun)
    roofs: list[tuple[int, int]] = []
    for oi in order:
        kind, i = objects[oi]
        if kind == "crown":
            _draw_crown(world.crowns[i], i, crown_data[i], cam, face_map, table, shadow_amount[oi])
            continue
        blk = world.blocks[i]
        gabled = blk.gable > 0.01
        templates = GABLE_FACES if gabled else BOX_FACES
        vis, lam, planes = faces[gabled]
        off = tuple(offsets_of[i])
        amount = shadow_amount[oi]
        for t, tmpl in enumerate(templates):
            if not vis[t][i]:
                continue
            sh = amount.get(t, 0.0) if isinstance(amount, dict) else amount
            if not gabled and t == 4:
                roof = blk.kind == "building"
                fid = table.add(HORIZONTAL, blk.label, blk.top, z=blk.z0 + blk.h, offset=off,
                                light=FaceLight(lambert=float(lam[t][i]), shadow=0.0 if roof else sh, roof=roof))
                if roof:
                    roofs.append((fid, i))
            else:
                fid = table.add(PLANAR, blk.label, blk.top if t >= 4 else blk.side, offset=off, plane=planes[t][i],
                                light=FaceLight(lambert=float(lam[t][i]), shadow=sh, ao=0.85 if t < 4 else 1.0))
            fill_polygon(face_map, pix[i, tmpl], int(fid), convex=True)
    return roofs


def _face_data(cam: _Camera, verts: np.ndarray, templates: tuple[list[int], ...], sun: np.ndarray
               ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Per template, for all blocks: visible (faces the camera), Lambert term and plane coefficients (B, 12)."""
    vis, lam, planes = [], [], []
    for (n, p0, e1, e2), tmpl in zip(_face_frames(verts, templates), templates, strict=True):
        centroid = verts[:, tmpl].mean(axis=1)
        vis.append(((cam.C - centroid) * n).sum(axis=1) > 1e-9)
        lam.append(np.maximum(n @ sun, 0.0))
        planes.append(_plane_coefficients(cam, n, p0, e1, e2))
    return vis, lam, planes


def _plane_coefficients(cam: _Camera, n: np.ndarray, p0: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """(..., 12) numbers giving a pixel's in-plane coordinates (u, v) on each face's plane."""
    k = ((p0 - cam.C) * n).sum(axis=-1, keepdims=True)
    u0 = ((cam.C - p0) * e1).sum(axis=-1, keepdims=True)
    v0 = ((cam.C - p0) * e2).sum(axis=-1, keepdims=True)
    return np.concatenate([cam.linear_form(n), k, cam.linear_form(e1), u0, cam.linear_form(e2), v0], axis=-1)


def _visible_crowns(world: World, cam: _Camera) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Crowns whose projection meets the image: crown index -> (blob points px, depths, bbox lo, bbox hi)."""
    if not world.crowns:
        return {}
    counts = np.array([len(c.blobs) for c in world.crowns])
    bl = np.concatenate([c.blobs for c in world.crowns])
    pts = bl[:, None, :3] + SPHERE[None] * np.stack([bl[:, 3], bl[:, 3], bl[:, 4]], axis=1)[:, None, :]
    pix, depth = cam.project(pts)
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    lo = np.minimum.reduceat(pix.min(axis=1), starts, axis=0)
    hi = np.maximum.reduceat(pix.max(axis=1), starts, axis=0)
    dmin = np.minimum.reduceat(depth.min(axis=1), starts)
    ok = (dmin > 0.5) & (hi[:, 0] >= -1) & (lo[:, 0] <= cam.W) & (hi[:, 1] >= -1) & (lo[:, 1] <= cam.H)
    out = {}
    for ci in np.flatnonzero(ok).tolist():
        s, e = starts[ci], starts[ci] + counts[ci]
        out[ci] = (pix[s:e], depth[s:e], lo[ci], hi[ci])
    return out


def _draw_crown(crown, ci: int, data: tuple[np.ndarray, ...], cam: _Camera, face_map: np.ndarray,
                table: FaceTable, shadow: np.ndarray | float) -> None:
    pix, depth = data[0], data[1]
    order = np.argsort(-depth.mean(axis=1), kind="stable")
    lo_all, hi_all = pix.min(axis=1), pix.max(axis=1)
    for bi in order.tolist():
        lo, hi = lo_all[bi], hi_all[bi]
        centre = (lo + hi) / 2
        half = np.maximum((hi - lo) / 2, 0.5)
        sh = float(shadow[bi]) if isinstance(shadow, np.ndarray) else float(shadow)
        off = ((ci * 7.77 + bi * 3.3) % 50.0, (ci * 5.13 + bi * 1.7) % 50.0)
        fid = table.add(CANOPY, crown.label, crown.look, light=FaceLight(shadow=sh), z=float(crown.blobs[bi, 2]),
                        offset=off, canopy=(float(centre[0]), float(centre[1]), float(half[0]), float(half[1])))
        fill_polygon(face_map, _leafy_outline(centre, half, ci * 31 + bi), int(fid))


_OUTLINE_ANGLES = np.linspace(0, 2 * np.pi, 48, endpoint=False)
_OUTLINE_JITTER = np.real(np.fft.ifft(np.fft.fft(np.random.default_rng(5).standard_normal((64, 48)), axis=1)
                                      * (np.minimum(np.arange(48), 48 - np.arange(48)) <= 10), axis=1))
_OUTLINE_JITTER /= _OUTLINE_JITTER.std(axis=1, keepdims=True)


def _leafy_outline(centre: np.ndarray, half: np.ndarray, key: int) -> np.ndarray:
    """A crown blob's outline in pixels: its projected ellipse with a ragged, leafy edge."""
    r = 1.0 + 0.06 * _OUTLINE_JITTER[key % len(_OUTLINE_JITTER)]
    return centre + np.stack([np.cos(_OUTLINE_ANGLES), np.sin(_OUTLINE_ANGLES)], axis=1) * half * r[:, None]


def _object_shadows(world: World, objects: list[tuple[str, int]], casters: Casters, sun: np.ndarray) -> list:
    """Per drawn object: shadow amount (blocks: float, or {wall index: amount} for buildings; crowns: per blob)."""
    if sun[2] <= 0.02:
        return [1.0 for _ in objects]
    pts, own_b, own_c, where = [], [], [], []
    for oi, (kind, i) in enumerate(objects):
        if kind == "crown":
            bl = world.crowns[i].blobs
            p = bl[:, :3] + sun[None] * (0.5 * bl[:, 3:4])
            for bi in range(len(bl)):
                pts.append(p[bi])
                own_b.append(-1)
                own_c.append(i)
                where.append((oi, bi))
            continue
        blk = world.blocks[i]
        if blk.kind == "building":
            c, s = math.cos(blk.angle), math.sin(blk.angle)
            u, v = np.array([c, s]), np.array([-s, c])
            mids = [-v * blk.l / 2, u * blk.w / 2, v * blk.l / 2, -u * blk.w / 2]
            for t, m in enumerate(mids):
                normal = m / np.linalg.norm(m)
                q = np.array([blk.cx, blk.cy]) + m + 0.05 * normal
                pts.append([q[0], q[1], blk.z0 + 0.45 * blk.h])
                own_b.append(i)
                own_c.append(-1)
                where.append((oi, t))
            if blk.gable > 0:
                for t in (4, 5):
                    pts.append([blk.cx, blk.cy, blk.z0 + blk.h + 0.6 * blk.gable])
                    own_b.append(i)
                    own_c.append(-1)
                    where.append((oi, t))
        else:
            pts.append([blk.cx, blk.cy, blk.top_z + 0.05])
            own_b.append(i)
            own_c.append(-1)
            where.append((oi, -1))
    amounts = casters.occlusion(np.array(pts, dtype=np.float64).reshape(-1, 3), sun,
                                own_block=np.array(own_b), own_crown=np.array(own_c))
    out: list = [0.0] * len(objects)
    for (oi, sub), amt in zip(where, amounts, strict=True):
        kind, i = objects[oi]
        if kind == "crown":
            if not isinstance(out[oi], np.ndarray):
                out[oi] = np.zeros(len(world.crowns[i].blobs), dtype=np.float32)
            out[oi][sub] = amt
        elif sub >= 0:
            if not isinstance(out[oi], dict):
                out[oi] = {}
            out[oi][sub] = float(amt)
        else:
            out[oi] = float(amt)
    return out


# -- shadows on the ground and on roofs ------------------------------------------------------------------
def _ground_shadows(world: World, cam: _Camera, clip: tuple[float, float, float, float], sun: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hard (solids) and soft (foliage) ground shadow masks and a contact-darkening mask, uint8 0/255."""
    hard = np.zeros((cam.H, cam.W), np.uint8)
    soft = np.zeros((cam.H, cam.W), np.uint8)
    ao = np.zeros((cam.H, cam.W), np.uint8)
    if sun[2] <= 0.02:
        hard[:] = 255
        return hard, soft, ao
    reach = 40.0 / max(math.tan(math.asin(min(sun[2], 1.0))), 0.2)
    xmin, xmax, ymin, ymax = clip
    if world.blocks:
        a = _block_arrays(world.blocks)
        near = ((a["cx"] > xmin - reach) & (a["cx"] < xmax + reach) & (a["cy"] > ymin - reach)
                & (a["cy"] < ymax + reach))
        idx = np.flatnonzero(near)
        if len(idx):
            sub = {k: v[idx] for k, v in a.items()}
            verts = _block_vertices(sub)
            ground = project_to_plane(verts, sun)
            pts = np.concatenate([ground, np.zeros(ground.shape[:-1] + (1,))], axis=-1)
            pix, depth = cam.project(pts)
            _fill_hulls(hard, pix, depth, cam)
            # contact darkening: building footprints grown by 1.5 m, blurred later
            tall = np.array([world.blocks[i].kind == "building" for i in idx])
            if tall.any():
                grown = {k: v[tall] for k, v in sub.items()}
                grown["w"] = grown["w"] + 3.0
                grown["l"] = grown["l"] + 3.0
                grown["h"] = np.zeros_like(grown["h"])
                grown["gable"] = np.zeros_like(grown["gable"])
                gpix, gdepth = cam.project(_block_vertices(grown)[:, :4])
                _fill_hulls(ao, gpix, gdepth, cam)
    blobs = [c.blobs for c in world.crowns
             if xmin - reach < c.blobs[0, 0] < xmax + reach and ymin - reach < c.blobs[0, 1] < ymax + reach]
    if blobs:
        bl = np.concatenate(blobs)
        pts3 = bl[:, None, :3] + SPHERE[None] * np.stack([bl[:, 3], bl[:, 3], bl[:, 4]], axis=1)[:, None, :]
        ground = project_to_plane(pts3, sun)
        pts = np.concatenate([ground, np.zeros(ground.shape[:-1] + (1,))], axis=-1)
        pix, depth = cam.project(pts)
        _fill_hulls(soft, pix, depth, cam)
    return hard, soft, ao


def _fill_hulls(mask: np.ndarray, pix: np.ndarray, depth: np.ndarray, cam: _Camera, value: int = 255,
                origin: tuple[int, int] = (0, 0)) -> None:
    """Fill the convex hull of each point group (G, P, 2) into ``mask`` (skipping groups behind the camera)."""
    H, W = mask.shape
    lo = pix.min(axis=1) - np.array(origin)
    hi = pix.max(axis=1) - np.array(origin)
    ok = (depth.min(axis=1) > 0.5) & (hi[:, 0] >= -1) & (lo[:, 0] <= W) & (hi[:, 1] >= -1) & (lo[:, 1] <= H)
    shifted = pix - np.array(origin)
    for g in np.flatnonzero(ok):
        hull = cv2.convexHull(shifted[g].astype(np.float32).reshape(-1, 1, 2)).reshape(-1, 2).astype(np.float64)
        fill_polygon(mask, hull, value, convex=True)


def _roof_shadows(world: World, cam: _Camera, face_map: np.ndarray, roofs: list[tuple[int, int]],
                  sun: np.ndarray, casters: Casters) -> np.ndarray:
    """Per-pixel shadows cast on flat roofs by taller solids, rooftop equipment and tree crowns."""
    mask = np.zeros(face_map.shape, np.uint8)
    if sun[2] <= 0.02 or not roofs:
        return mask
    tan_el = math.tan(math.asin(min(sun[2], 1.0)))
    bx = casters.boxes
    for fid, bi in roofs:
        blk = world.blocks[bi]
        zr = blk.z0 + blk.h
        radius = math.hypot(blk.w, blk.l) / 2
        groups = []
        if len(bx):
            reach = radius + np.hypot(bx[:, 4], bx[:, 5]) + np.maximum(bx[:, 7] - zr, 0) / max(tan_el, 0.05)
            near = ((bx[:, 7] > zr + 0.1) & (np.hypot(bx[:, 0] - blk.cx, bx[:, 1] - blk.cy) < reach)
                    & (casters.box_owner != bi))
            for m in np.flatnonzero(near):
                c = world.blocks[int(casters.box_owner[m])]
                verts = _block_vertices(_block_arrays([c]))[0]
                verts[:, 2] = np.maximum(verts[:, 2], zr)
                groups.append(project_to_plane(verts, sun, zr))
        if len(casters.blobs):
            bl = casters.blobs
            reach = radius + bl[:, 3] + np.maximum(bl[:, 2] + bl[:, 4] - zr, 0) / max(tan_el, 0.05)
            near = (bl[:, 2] + bl[:, 4] > zr) & (np.hypot(bl[:, 0] - blk.cx, bl[:, 1] - blk.cy) < reach)
            for m in np.flatnonzero(near):
                pts3 = bl[m, :3] + SPHERE * np.array([bl[m, 3], bl[m, 3], bl[m, 4]])
                pts3[:, 2] = np.maximum(pts3[:, 2], zr)
                groups.append(project_to_plane(pts3, sun, zr))
        if not groups:
            continue
        roof_poly = _roof_pixels_bbox(world.blocks[bi], cam)
        if roof_poly is None:
            continue
        c0, r0, c1, r1 = roof_poly
        crop = np.zeros((r1 - r0, c1 - c0), np.uint8)
        for grp in groups:
            pts = np.concatenate([grp, np.full((len(grp), 1), zr)], axis=1)
            pix, depth = cam.project(pts)
            _fill_hulls(crop, pix[None], depth[None], cam, origin=(c0, r0))
        sel = face_map[r0:r1, c0:c1] == fid
        mask[r0:r1, c0:c1][sel & (crop > 0)] = 255
    return mask


def _roof_pixels_bbox(blk, cam: _Camera) -> tuple[int, int, int, int] | None:
    """Image bounding box (c0, r0, c1, r1) of a block's roof, clipped to the image."""
    verts = _block_vertices(_block_arrays([blk]))
    pix, _ = cam.project(verts[0, 4:8])
    c0, r0 = np.floor(pix.min(axis=0)).astype(int) - 1
    c1, r1 = np.ceil(pix.max(axis=0)).astype(int) + 2
    c0, r0 = max(c0, 0), max(r0, 0)
    c1, r1 = min(c1, cam.W), min(r1, cam.H)
    if c1 <= c0 or r1 <= r0:
        return None
    return int(c0), int(r0), int(c1), int(r1)
