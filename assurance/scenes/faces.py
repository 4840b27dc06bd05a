"""The face table: one row per drawn polygon, read back per pixel through the face-id map.

Rendering fills a face-id map (int32, one id per pixel, 0 = nothing) with projected polygons;
labels, materials, colours and lighting are then gathered per pixel from this table. A face is
one of four kinds: ground (textured in world x, y), horizontal (a flat top at height z),
planar (a wall or roof slope, textured in its own plane coordinates) or canopy (a crown blob).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from assurance.scenes.materials import MATERIALS
from assurance.scenes.world import Look

GROUND, HORIZONTAL, PLANAR, CANOPY = 0, 1, 2, 3


@dataclass
class FaceArrays:
    """Per-face lookup tables (index = face id), float32 unless stated."""

    kind: np.ndarray  # uint8
    label: np.ndarray  # uint8
    rgb: np.ndarray  # (n, 3)
    cell_rgb: np.ndarray  # (n, 3)
    cell: np.ndarray  # (n, 4) size_u, size_v, half_u, half_v; size 0 = no cells
    cell_var: np.ndarray
    noise: np.ndarray  # (n, 4) octave amplitudes
    chroma: np.ndarray
    grain: np.ndarray
    lambert: np.ndarray
    shadow: np.ndarray  # object-level shadow amount
    ao: np.ndarray
    z: np.ndarray
    offset: np.ndarray  # (n, 2) texture offset (m)
    plane: np.ndarray  # (n, 12) planar surface-coordinate coefficients
    canopy: np.ndarray  # (n, 4) centre col, row and half-extents in pixels
    roof: np.ndarray  # bool: a building's flat top (receives per-pixel roof shadows)


@dataclass(frozen=True)
class FaceLight:
    """How a face is lit: its ``lambert`` term (the sun on it), the object-level ``shadow`` amount, its ambient
    occlusion ``ao``, and ``roof``: a building's flat top, which receives per-pixel roof shadows."""

    lambert: float = 0.0
    shadow: float = 0.0
    ao: float = 1.0
    roof: bool = False


NO_LIGHT = FaceLight()


class FaceTable:
    """Collects faces while drawing; ``arrays()`` freezes them into lookup tables."""

    def __init__(self) -> None:
        self._rows: list[tuple] = []
        self._planes: dict[int, np.ndarray] = {}
        self._canopies: dict[int, tuple[float, float, float, float]] = {}

    def __len__(self) -> int:
        return len(self._rows) + 1

    def add(self, kind: int, label: int, look: Look, *, light: FaceLight = NO_LIGHT, z: float = 0.0,
            offset: tuple[float, float] = (0.0, 0.0), plane: np.ndarray | None = None,
            canopy: tuple[float, float, float, float] | None = None) -> int:
        """Register a face lit as ``light`` says; returns its id (>= 1)."""
        fid = len(self._rows) + 1
        self._rows.append((kind, label, look, light.lambert, light.shadow, light.ao, z, offset, light.roof))
        if plane is not None:
            self._planes[fid] = plane
        if canopy is not None:
            self._canopies[fid] = canopy
        return fid

    def arrays(self) -> FaceArrays:
        n = len(self._rows) + 1
        f32 = np.float32
        kind = np.zeros(n, np.uint8)
        label = np.zeros(n, np.uint8)
        rgb = np.zeros((n, 3), f32)
        cell_rgb = np.zeros((n, 3), f32)
        cell = np.zeros((n, 4), f32)
        cell_var = np.zeros(n, f32)
        noise = np.zeros((n, 4), f32)
        chroma = np.zeros(n, f32)
        grain = np.zeros(n, f32)
        lambert = np.zeros(n, f32)
        shadow = np.zeros(n, f32)
        ao = np.ones(n, f32)
        z = np.zeros(n, f32)
        offset = np.zeros((n, 2), f32)
        roof = np.zeros(n, bool)
        for i, (k, lab, look, lam, sh, a, zz, off, rf) in enumerate(self._rows, start=1):
            m = MATERIALS[look.material]
            kind[i], label[i] = k, lab
            rgb[i] = look.rgb
            grid = look.cell or m.cell
            if grid is not None:
                cell[i] = grid
                cell_rgb[i] = look.cell_rgb if look.cell_rgb is not None else np.asarray(look.rgb) * m.cell_gain
                cell_var[i] = m.cell_var
            noise[i] = m.noise
            chroma[i], grain[i] = m.chroma, m.grain
            lambert[i], shadow[i], ao[i], z[i] = lam, sh, a, zz
            offset[i] = off
            roof[i] = rf
        plane = np.zeros((n, 12), np.float64)
        for fid, p in self._planes.items():
            plane[fid] = p
        canopy = np.zeros((n, 4), f32)
        for fid, c in self._canopies.items():
            canopy[fid] = c
        np.clip(cell_rgb, 0, 1, out=cell_rgb)
        return FaceArrays(kind, label, rgb, cell_rgb, cell, cell_var, noise, chroma, grain, lambert, shadow, ao,
                          z, offset, plane, canopy, roof)
