"""Tileable noise textures and their sampling at world coordinates (metres) with OpenCV's remap.

Five tiles carry the four noise octaves and a colour-drift field in two groups that share one
coordinate computation each: fine (0.14 m and 0.55 m) and coarse (2.2 m, 9 m and the drift).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

TILE = 1024
TEXELS_PER_FEATURE = 6.0


def _smooth_noise(rng: np.random.Generator, feature_texels: float) -> np.ndarray:
    """Periodic Gaussian-filtered white noise (TILE, TILE), zero mean, unit variance."""
    white = rng.standard_normal((TILE, TILE))
    f = np.fft.fftfreq(TILE)
    sigma = feature_texels / 2.5
    gain = np.exp(-2 * (np.pi * sigma) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    out = np.real(np.fft.ifft2(np.fft.fft2(white) * gain))
    return ((out - out.mean()) / out.std()).astype(np.float32)


@lru_cache(maxsize=1)
def octave_tiles() -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(fine, coarse) single-channel tiles sampled with shared coordinates.

    fine = [0.14 m octave, 0.55 m octave] at FINE_SCALE_M; coarse = [2.2 m octave, 9 m octave,
    4.4 m colour drift] at COARSE_SCALE_M.
    """
    rng = np.random.default_rng(9137)
    t = TEXELS_PER_FEATURE
    fine = [_smooth_noise(rng, t), _smooth_noise(rng, t * 0.55 / 0.14)]
    coarse = [_smooth_noise(rng, t), _smooth_noise(rng, t * 9.0 / 2.2), _smooth_noise(rng, t * 2.0)]
    return fine, coarse


FINE_SCALE_M = 0.14  # feature size (m) of the first fine tile
COARSE_SCALE_M = 2.2  # feature size (m) of the first coarse tile


def sample(tiles: list[np.ndarray], u: np.ndarray, v: np.ndarray, scale_m: float, offset: tuple[float, float]
           ) -> list[np.ndarray]:
    """Sample tiles at world coordinates (u, v) in metres (first tile's feature size = scale_m)."""
    k = np.float32(TEXELS_PER_FEATURE / scale_m)
    maps = []
    for coord, off in ((u, offset[0]), (v, offset[1])):
        m = coord * k
        m += np.float32(off)
        w = m * np.float32(1.0 / TILE)
        np.floor(w, out=w)
        w *= np.float32(TILE)
        m -= w
        maps.append(m)
    return [cv2.remap(t, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP) for t in tiles]


@lru_cache(maxsize=4)
def grain_field(rows: int, cols: int) -> np.ndarray:
    """Screen-space white noise (3, rows, cols) int8 in [-127, 127], fixed; sliced per band."""
    rng = np.random.default_rng(4242)
    return rng.integers(-127, 128, (3, rows, cols), dtype=np.int8)
