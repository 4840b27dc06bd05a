"""Per-pixel shading of a face-id map: textures in metric surface coordinates, sun and sky light,
shadows, haze, colour grading, sensor grain and optical blur.

Work is done in horizontal bands of rows so that the float buffers stay small at 3840x2160.
Every surface is textured in its own metres (ground x, y; roofs at their height; walls along the
wall and up), so texture scale follows the perspective like a real camera's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from assurance.scenes.faces import CANOPY, GROUND, HORIZONTAL, PLANAR, FaceArrays
from assurance.scenes.materials import OCTAVE_SCALES_M
from assurance.scenes.styles import LIGHTINGS
from assurance.scenes.textures import COARSE_SCALE_M, FINE_SCALE_M, TILE, grain_field, octave_tiles, sample
from assurance.scenes.world import World
from el.geometry.camera import CameraGeometry

BAND_ROWS = 270


@dataclass
class ShadeInputs:
    """What the shader needs besides the face map: camera, world (sun, grading) and shadow masks."""

    geometry: CameraGeometry
    world: World
    sun: np.ndarray
    hard: np.ndarray  # uint8 ground shadows of solids
    soft: np.ndarray  # uint8 ground shadows of foliage
    roof: np.ndarray  # uint8 shadows on flat roofs
    ao: np.ndarray | None = None  # uint8 contact darkening near building bases (blurred here)


def shade(face_map: np.ndarray, faces: FaceArrays, inp: ShadeInputs) -> np.ndarray:
    """RGB uint8 image (H, W, 3) of the face map."""
    H, W = face_map.shape
    ctx = _Context(inp.geometry, inp, faces)
    out = np.empty((H, W, 3), np.uint8)
    for r0 in range(0, H, BAND_ROWS):
        r1 = min(H, r0 + BAND_ROWS)
        out[r0:r1] = ctx.band(face_map[r0:r1], r0, r1)
    cv2.LUT(out, ctx.tone_lut, dst=out)
    sigma = float(inp.world.grade.get("blur_px", 0.6))
    if sigma > 0.05:
        cv2.GaussianBlur(out, (0, 0), sigma, dst=out)
    return out


def _f32(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float32)


class _Context:
    """Per-image constants (lookup tables, light, grading) and the per-band shading routine."""

    def __init__(self, g: CameraGeometry, inp: ShadeInputs, faces: FaceArrays) -> None:
        self.g, self.inp, self.faces = g, inp, faces
        self.W, self.H = g.width, g.height
        self.Hc = g.pose.height_m
        self.st, self.ct = math.sin(g.theta), math.cos(g.theta)
        self.f = g.f_px
        W = self.W
        self._set_shadow_maps(inp)
        phi = math.radians(inp.world.grid_angle_deg)
        cols = np.arange(W, dtype=np.float32) - W / 2 + 0.5
        self.h = cols
        self.h_c = _f32(cols * math.cos(phi))
        self.h_ms = _f32(-cols * math.sin(phi))
        self.cphi, self.sphi = math.cos(phi), math.sin(phi)
        self._set_grading(inp, cols)
        self._set_face_tables(faces, float(inp.world.grade.get("saturation", 1.0)))
        # textures and screen grain
        seed = int(inp.world.seed)
        rs = np.random.default_rng(seed + 99)
        self.tex_off = rs.uniform(0, TILE, (2, 2))
        self.grain_rows = (int(rs.integers(0, 64)), int(rs.integers(0, 64)))
        self.fine_tiles, self.coarse_tiles = octave_tiles()
        self.grain_field = grain_field(BAND_ROWS + 64, W + 64)
        _, along, _ = g.pixel_size(np.arange(self.H))
        self.pix_along = np.nan_to_num(along, nan=10.0, posinf=10.0).astype(np.float32)
        # camera axes in world coordinates (x right, y down, z forward) and the sun in them
        x_c = np.array([1.0, 0.0, 0.0])
        y_c = np.array([0.0, -self.st, -self.ct])
        z_c = np.array([0.0, self.ct, -self.st])
        sun = inp.sun
        self.sun_cam = np.array([sun @ x_c, sun @ y_c, sun @ z_c], np.float32)

    def _set_shadow_maps(self, inp: ShadeInputs) -> None:
        """Soften the ground shadow masks (foliage more than solids) and spread the contact darkening."""
        W, g = self.W, self.g
        self.soft = cv2.GaussianBlur(inp.soft, (0, 0), max(0.6, 1.6 * W / 3840))
        self.hard = cv2.GaussianBlur(inp.hard, (0, 0), max(0.5, 1.2 * W / 3840))
        self.contact = None
        if inp.ao is not None and inp.ao.any():
            small = cv2.resize(inp.ao, (max(1, W // 4), max(1, g.height // 4)), interpolation=cv2.INTER_AREA)
            small = cv2.GaussianBlur(small, (0, 0), max(0.8, 3.0 * W / 3840))
            self.contact = cv2.resize(small, (W, g.height), interpolation=cv2.INTER_LINEAR)

    def _set_grading(self, inp: ShadeInputs, cols: np.ndarray) -> None:
        """Sun, sky and haze colours (white balance and exposure folded in), sensor noise, vignette, tone curve."""
        grade = inp.world.grade
        light = LIGHTINGS.get(inp.world.lighting, LIGHTINGS["noon"])
        W = self.W
        # auto-exposure: a mid-grey lit ground reads the same under every light, then the grade varies it
        lum = np.array([0.299, 0.587, 0.114])
        ref = float(lum @ light.ambient + (lum @ light.sun) * max(float(inp.sun[2]), 0.0))
        exposure = float(grade.get("exposure", 1.0)) * 1.1 / max(ref, 0.3)
        wb = np.array(grade.get("white_balance", (1.0, 1.0, 1.0)), np.float32)
        self.sun_rgb = np.array(light.sun, np.float32) * wb * exposure
        self.amb_rgb = np.array(light.ambient, np.float32) * wb * exposure
        self.haze = float(grade.get("haze", light.haze))
        self.haze_rgb = np.array(grade.get("haze_rgb", (0.72, 0.75, 0.80)), np.float32) * exposure
        self.noise_sigma = float(grade.get("sensor_noise", 0.012)) / 127.0
        vignette = float(grade.get("vignette", 0.15))
        xs = cols / (W / 2)
        self.vig_col = _f32(1 - vignette * 0.5 * xs**2)
        self.vignette = vignette
        contrast, gamma = float(grade.get("contrast", 1.0)), float(grade.get("gamma", 1.0))
        x = np.arange(256) / 255.0
        tone = np.clip((x - 0.45) * contrast + 0.45, 0, 1) ** gamma
        self.tone_lut = np.clip(tone * 255 + 0.5, 0, 255).astype(np.uint8)

    def _set_face_tables(self, faces: FaceArrays, sat: float) -> None:
        """Per-face lookup tables (albedo with the grade's saturation, cells, noise, light, planes) for ``take``."""
        lum = faces.rgb @ np.array([0.299, 0.587, 0.114], np.float32)
        rgb = lum[:, None] + (faces.rgb - lum[:, None]) * sat
        self.rgb = [_f32(np.clip(rgb[:, c], 0, 1)) for c in range(3)]
        clum = faces.cell_rgb @ np.array([0.299, 0.587, 0.114], np.float32)
        cell_rgb = np.clip(clum[:, None] + (faces.cell_rgb - clum[:, None]) * sat, 0, 1)
        self.cell_rgb = [_f32(cell_rgb[:, c]) for c in range(3)]
        cell = faces.cell.astype(np.float64)
        with np.errstate(divide="ignore"):
            self.inv_su = _f32(np.where(cell[:, 0] > 0, 1 / cell[:, 0], 0))
            self.inv_sv = _f32(np.where(cell[:, 1] > 0, 1 / cell[:, 1], 0))
        self.half_u, self.half_v = _f32(cell[:, 2]), _f32(cell[:, 3])
        self.min_cell = _f32(np.minimum(cell[:, 0], cell[:, 1]))
        self.cell_area = _f32(np.clip(4 * cell[:, 2] * cell[:, 3], 0, 1))
        self.cell_var = _f32(faces.cell_var)
        self.kind = np.ascontiguousarray(faces.kind)
        zscale = np.ones(len(faces.kind), np.float32)
        elevated = (faces.kind == HORIZONTAL) | (faces.kind == CANOPY)
        zscale[elevated] = (self.Hc - faces.z[elevated]) / self.Hc
        self.zscale = zscale
        self.offu, self.offv = _f32(faces.offset[:, 0]), _f32(faces.offset[:, 1])
        self.amp = [_f32(faces.noise[:, k]) for k in range(4)]
        self.chroma = _f32(faces.chroma)
        self.grain = _f32(faces.grain / 127.0)
        self.lambert, self.ao, self.shadow = _f32(faces.lambert), _f32(faces.ao), _f32(faces.shadow)
        self.roof = faces.roof.astype(np.uint8)
        self.has_cell = (faces.cell[:, 0] > 0).astype(np.uint8)
        self.plane_cols = [_f32(faces.plane[:, k]) for k in range(12)]
        self.tint = np.array([0.4, 0.15, -0.45], np.float32)

    def band(self, fm: np.ndarray, r0: int, r1: int) -> np.ndarray:
        """RGB uint8 of image rows ``r0:r1`` from their face ids (the tone curve and blur come after)."""
        fm = fm.astype(np.intp)  # numpy's take converts indices to intp on every call otherwise
        rows = np.arange(r0, r1, dtype=np.float32)
        su, sv, kind = self._surface_coords(fm, rows, r0)
        col = [self.rgb[c].take(fm) for c in range(3)]
        cells = np.flatnonzero(self.has_cell.take(fm))
        if len(cells):
            self._cells(fm, cells, su, sv, col, r0)
        # noise octaves (with level of detail per row), grain and colour drift
        n3, n2 = sample(self.fine_tiles, su, sv, FINE_SCALE_M, tuple(self.tex_off[0]))
        n1, n0, drift = sample(self.coarse_tiles, su, sv, COARSE_SCALE_M, tuple(self.tex_off[1]))
        del su, sv
        go = (self.grain_rows[0] + r0 * 7) % 64
        self._texture(fm, (n0, n1, n2, n3), drift, col, r0, r1, go)
        lit, ao = self._light(fm, kind, n1, r0, r1)
        self._expose(col, lit, ao, rows, r0, r1, go)
        img = cv2.merge(col)
        return cv2.convertScaleAbs(img, alpha=255.0)

    def _surface_coords(self, fm: np.ndarray, rows: np.ndarray, r0: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Surface coordinates (m) of each pixel of the band, and its face kind.

        Ground and flat tops are in the street frame (tops scaled to their height), walls in their plane.
        """
        v = rows - self.H / 2 + 0.5
        den = v * self.ct + self.f * self.st
        t = np.where(den > 1e-6, self.Hc / np.maximum(den, 1e-6), 1e4).astype(np.float32)
        yrow = t * (self.f * self.ct - v * self.st)
        su = t[:, None] * self.h_c[None, :]
        su += (yrow * self.sphi)[:, None]
        sv = t[:, None] * self.h_ms[None, :]
        sv += (yrow * self.cphi)[:, None]
        zs = self.zscale.take(fm)
        su *= zs
        sv *= zs
        del zs
        su += self.offu.take(fm)
        sv += self.offv.take(fm)
        kind = self.kind.take(fm)
        planar = np.flatnonzero(kind == PLANAR)
        if len(planar):
            self._planar_coords(fm, planar, r0, su, sv)
        return su, sv, kind

    def _texture(self, fm: np.ndarray, octaves: tuple[np.ndarray, ...], drift: np.ndarray, col: list[np.ndarray],
                 r0: int, r1: int, go: int) -> None:
        """Modulate the albedo ``col`` in place by the noise octaves (fading with distance), grain and drift.

        The second octave is copied before scaling: the caller reuses it for the foliage shadow dapple.
        """
        nrows, W = fm.shape
        pix = self.pix_along[r0:r1]
        m = np.ones(fm.shape, np.float32)
        for k, (scale, n) in enumerate(zip(OCTAVE_SCALES_M, octaves, strict=True)):
            lod = np.clip(scale / (2.5 * pix) - 0.3, 0.0, 1.0).astype(np.float32)
            if k >= 2:
                n = n * lod[:, None]
            else:
                n = n.copy() if k == 1 else n
            n *= self.amp[k].take(fm)
            m += n
        grain = self.grain_field[0, go:go + nrows, 32:32 + W]
        m += self.grain.take(fm) * grain
        np.maximum(m, 0.05, out=m)
        drift *= self.chroma.take(fm)
        for c in range(3):
            f = drift * self.tint[c]
            f += 1
            f *= m
            col[c] *= f

    def _light(self, fm: np.ndarray, kind: np.ndarray, n1: np.ndarray, r0: int, r1: int
               ) -> tuple[np.ndarray, np.ndarray]:
        """Direct sun (Lambert, shadows dappled by the noise octave ``n1``) and sky light (ambient occlusion)."""
        direct = self.lambert.take(fm)
        ao = self.ao.take(fm)
        canopy = np.flatnonzero(kind == CANOPY)
        if len(canopy):
            self._canopy_light(fm, canopy, r0, direct, ao)
        shadow = self.shadow.take(fm)
        dapple = n1
        dapple *= 0.3
        dapple += 0.62
        np.clip(dapple, 0, 1, out=dapple)
        g_sh = self.soft[r0:r1] * np.float32(1 / 255)
        g_sh *= dapple
        np.maximum(g_sh, self.hard[r0:r1] * np.float32(1 / 255), out=g_sh)
        ground = kind == GROUND
        shadow = np.where(ground, g_sh, shadow)
        if self.contact is not None:
            dark = self.contact[r0:r1] * np.float32(-0.35 / 255)
            dark += 1
            ao = np.where(ground, ao * dark, ao)
        roof = self.roof.take(fm)
        if roof.any():
            shadow = np.where(roof > 0, self.inp.roof[r0:r1] * np.float32(1 / 255), shadow)
        lit = 1 - shadow
        lit *= direct
        return lit, ao

    def _expose(self, col: list[np.ndarray], lit: np.ndarray, ao: np.ndarray, rows: np.ndarray, r0: int, r1: int,
                go: int) -> None:
        """Light ``col`` in place, with haze growing with range, vignetting and sensor noise."""
        nrows, W = lit.shape
        gf = self.grain_field
        dist = self.Hc / np.clip(np.sin(self.g.depression(np.arange(r0, r1))), 0.05, 1.0)
        haze = (self.haze * np.clip(dist / 120.0, 0, 2)).astype(np.float32)
        ys = (rows - self.H / 2) / (self.H / 2)
        row_gain = ((1 - haze) * (1 - self.vignette * 0.5 * ys**2)).astype(np.float32)
        gain = self.vig_col[None, :] * row_gain[:, None]
        sens = self.noise_sigma
        for c in range(3):
            light = lit * self.sun_rgb[c]
            light += ao * self.amb_rgb[c]
            light *= gain
            col[c] *= light
            col[c] += (haze * self.haze_rgb[c])[:, None]
            col[c] += sens * gf[c, go:go + nrows, 16:16 + W]

    def _planar_coords(self, fm: np.ndarray, idx: np.ndarray, r0: int, su: np.ndarray, sv: np.ndarray) -> None:
        """In-plane (u, v) metres of walls and roof slopes from their plane coefficients."""
        fid = fm.ravel().take(idx)
        rr, cc = np.divmod(idx, self.W)
        hh = cc.astype(np.float32)
        hh -= np.float32(self.W / 2 - 0.5)
        vv = rr.astype(np.float32)
        vv += np.float32(r0 - self.H / 2 + 0.5)
        P = self.plane_cols

        def form(k: int) -> np.ndarray:
            out = P[k].take(fid)
            out *= hh
            t = P[k + 1].take(fid)
            t *= vv
            out += t
            out += P[k + 2].take(fid)
            return out

        s = form(0)
        s[np.abs(s) < 1e-6] = 1e-6
        np.divide(P[3].take(fid), s, out=s)
        u = form(4)
        u *= s
        u += P[7].take(fid)
        u += self.offu.take(fid)
        w = form(8)
        w *= s
        w += P[11].take(fid)
        w += self.offv.take(fid)
        su.ravel()[idx] = u
        sv.ravel()[idx] = w

    def _cells(self, fm: np.ndarray, idx: np.ndarray, su: np.ndarray, sv: np.ndarray, col: list[np.ndarray],
               r0: int) -> None:
        """Pavers, slabs, windows, roof tiles and ribs: a cell grid with per-cell colour variation."""
        fid = fm.ravel().take(idx)
        u = su.ravel().take(idx)
        u *= self.inv_su.take(fid)
        v = sv.ravel().take(idx)
        v *= self.inv_sv.take(fid)
        iu, iv = np.floor(u), np.floor(v)
        u -= iu
        v -= iv
        u -= 0.5
        v -= 0.5
        inside = (np.abs(u) < self.half_u.take(fid)) & (np.abs(v) < self.half_v.take(fid))
        h = (iu.astype(np.int32) * 73856093) ^ (iv.astype(np.int32) * 19349663) ^ (fid * 83492791)
        rnd = (h & 0xFFFF).astype(np.float32)
        rnd *= np.float32(2 / 65535.0)
        rnd -= 1
        rnd *= self.cell_var.take(fid)
        rnd += 1
        # weight of the cell colour: exact inside/outside when cells span pixels, their area when not
        px = self.pix_along[r0:][idx // self.W]
        fade = self.min_cell.take(fid) / px
        fade -= 2.0
        fade *= np.float32(1 / 3)
        np.clip(fade, 0, 1, out=fade)
        area = self.cell_area.take(fid)
        wgt = inside.astype(np.float32)
        wgt -= area
        wgt *= fade
        wgt += area
        for c in range(3):
            flat = col[c].ravel()
            base = flat.take(idx)
            cc = self.cell_rgb[c].take(fid)
            cc *= rnd
            cc -= base
            cc *= wgt
            cc += base
            flat[idx] = cc

    def _canopy_light(self, fm: np.ndarray, idx: np.ndarray, r0: int, direct: np.ndarray, ao: np.ndarray) -> None:
        """Sphere-like lighting of crown blobs from their projected centre and half-extents."""
        fid = fm.ravel()[idx]
        cp = self.faces.canopy[fid]
        rr, cc = np.divmod(idx, self.W)
        dx = (cc - cp[:, 0]) / cp[:, 2] * np.float32(0.8)
        dy = (rr + r0 - cp[:, 1]) / cp[:, 3] * np.float32(0.8)
        r2 = np.clip(dx * dx + dy * dy, 0, 1)
        nz = np.sqrt(1 - r2)
        s = self.sun_cam
        ndots = dx * s[0] + dy * s[1] - nz * s[2]
        direct.ravel()[idx] = np.clip((ndots + 0.3) / 1.3, 0, 1)
        ao.ravel()[idx] = 0.7 + 0.3 * nz
