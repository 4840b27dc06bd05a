"""Hazard of a landing candidate: H = alpha H_s + (1 - alpha) H_d (docs/architecture.md section 3.5).

Pure functions on arrays, no state. Coordinates are working-resolution pixel indices (row, col);
a disc of radius R around pixel (i, j) holds the pixels whose centres lie within R of its centre.

- ``H_s = sum_l m_l s_l / max_l s_l`` with ``m_l`` the mean probability of class l over the disc
  and ``s_l`` the hazard score of class l (the label set's ``hazard_scores``, default
  ``el.classes.labels.UAVID``; 0 for forbidden classes).
- ``H_d = (d - d_max) / (R - d_max)`` if ``d < d_max`` else 0, ``d_max = d_max_factor * R``,
  with ``d`` the clearance (px) from the centre to the nearest forbidden pixel.

Both terms are clipped to [0, 1], so H lies in [0, 1] for any alpha in [0, 1].
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from el.classes.labels import LabelSet


@lru_cache(maxsize=256)
def _sq_grid(n: int) -> np.ndarray:
    yy, xx = np.mgrid[-n : n + 1, -n : n + 1]
    grid = (yy * yy + xx * xx).astype(np.float64)
    grid.flags.writeable = False
    return grid


def disc_mask(radius: float) -> np.ndarray:
    """Boolean (2n+1, 2n+1) mask of the offsets within ``radius`` of the centre, n = floor(radius)."""
    if not (math.isfinite(radius) and radius >= 0):
        raise ValueError(f"radius must be finite and >= 0, got {radius!r}")
    return _sq_grid(int(math.floor(radius))) <= radius * radius


def semantic_hazard(
    probs: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    radii: np.ndarray,
    scores: np.ndarray | None = None,
    *,
    labels: LabelSet,
) -> np.ndarray:
    """H_s of discs centred on pixels (rows, cols) with radii ``radii`` (px), shape (n,).

    ``probs`` is (C, H, W) class probabilities; the part of a disc outside the image is ignored
    (a valid candidate's disc lies inside it). Only a crop around each disc is touched, and only
    the classes with a non-zero score. ``scores``: the hazard score per class, by default
    ``labels.hazard_scores``.
    """
    scores = np.asarray(labels.hazard_scores if scores is None else scores, dtype=np.float64)
    if probs.ndim != 3 or probs.shape[0] != scores.shape[0]:
        raise ValueError(f"probs must be ({scores.shape[0]}, H, W), got {probs.shape}")
    smax = float(scores.max())
    _, h, w = probs.shape
    out = np.zeros(len(rows), dtype=np.float64)
    if smax <= 0:
        return out
    weighted = [(int(c), np.float32(scores[c] / smax)) for c in np.flatnonzero(scores > 0)]
    for k, (i, j, r) in enumerate(zip(np.asarray(rows), np.asarray(cols), np.asarray(radii), strict=True)):
        mask = disc_mask(float(r))
        n = mask.shape[0] // 2
        i0, i1, j0, j1 = int(i) - n, int(i) + n + 1, int(j) - n, int(j) + n + 1
        ci0, ci1, cj0, cj1 = max(i0, 0), min(i1, h), max(j0, 0), min(j1, w)
        m = mask[ci0 - i0 : ci1 - i0, cj0 - j0 : cj1 - j0]
        count = int(m.sum())
        if count == 0:
            continue
        score = np.zeros(m.shape, dtype=np.float32)
        for c, wgt in weighted:
            score += wgt * probs[c, ci0:ci1, cj0:cj1]
        out[k] = float(score[m].sum(dtype=np.float64)) / count
    return np.clip(out, 0.0, 1.0)


def distance_hazard(clearance: np.ndarray, radii: np.ndarray, d_max_factor: float = 3.0) -> np.ndarray:
    """H_d from the clearance ``d`` (px) at each centre and the radius R (px) that validated it."""
    d = np.asarray(clearance, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    if d_max_factor <= 1:
        raise ValueError(f"d_max_factor must be > 1, got {d_max_factor!r}")
    d_max = d_max_factor * r
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.where(d < d_max, (d - d_max) / (r - d_max), 0.0)
    h = np.where(np.isnan(h), 1.0, h)  # a degenerate radius counts as the worst case
    return np.clip(h, 0.0, 1.0)


def combined_hazard(h_s: np.ndarray, h_d: np.ndarray, alpha: float = 0.5) -> np.ndarray:
    """H = alpha H_s + (1 - alpha) H_d, in [0, 1]."""
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must lie in [0, 1], got {alpha!r}")
    h = alpha * np.asarray(h_s, dtype=np.float64) + (1.0 - alpha) * np.asarray(h_d, dtype=np.float64)
    return np.clip(h, 0.0, 1.0)


def rank_order(hazards: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Indices sorting candidates by increasing hazard; ties broken by row, then column (deterministic)."""
    return np.lexsort((np.asarray(cols), np.asarray(rows), np.asarray(hazards)))
