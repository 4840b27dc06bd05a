"""One disc rasterisation: the LHD monitor's patch mask and the ground truth cover the same pixels."""

from __future__ import annotations

import numpy as np
import pytest

from assurance.campaign.truth import disc_pixels
from el.base.decision import Disc
from el.geometry.discs import disc_bounds, disc_window_mask
from el.monitors.patches import extract_patch


def _patch_pixels(shape: tuple[int, int], disc: Disc, margin: float) -> set[int]:
    """Flat indices of the full-resolution pixels the monitor's patch marks as in the disc."""
    h, w = shape
    patch = extract_patch(np.zeros((h, w, 3), np.uint8), disc, margin=margin)
    x0, y0 = patch.offset
    rows, cols = np.nonzero(patch.disc_mask)
    return set(((rows + y0) * w + (cols + x0)).tolist())


def _truth_pixels(shape: tuple[int, int], disc: Disc) -> set[int]:
    """Flat indices of the pixels the ground truth counts (a label map holding each pixel's index)."""
    h, w = shape
    return set(disc_pixels(np.arange(h * w, dtype=np.int64).reshape(h, w), disc).tolist())


@pytest.mark.parametrize("seed", range(8))
def test_monitor_and_ground_truth_agree_on_random_discs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(40, 200)), int(rng.integers(40, 300)))
    for _ in range(60):
        h, w = shape
        r = float(rng.uniform(0.6, 30.0)) if rng.random() < 0.8 else float(rng.integers(1, 20))
        x = float(rng.uniform(-0.5 * r, w + 0.5 * r)) if rng.random() < 0.3 else float(rng.uniform(r, w - r))
        y = float(rng.uniform(-0.5 * r, h + 0.5 * r)) if rng.random() < 0.3 else float(rng.uniform(r, h - r))
        if rng.random() < 0.3:  # centres on pixel centres and corners: boundary pixels at exactly r
            x, y = round(x) + 0.5 * int(rng.integers(0, 2)), round(y) + 0.5 * int(rng.integers(0, 2))
        disc = Disc(x, y, r)
        truth = _truth_pixels(shape, disc)
        try:
            patch = _patch_pixels(shape, disc, margin=float(rng.choice([0.0, 0.25, 1.0])))
        except ValueError:  # no pixel of the disc inside the image: the monitor refuses it
            assert truth == set()
            continue
        assert patch == truth, (shape, disc)


def test_boundary_pixels_are_in_the_disc() -> None:
    # The centre of pixel (row 10, col 13) is 3 px right of the disc's centre: exactly on its edge.
    disc = Disc(10.5, 10.5, 3.0)
    x0, y0, x1, y1 = disc_bounds(disc, 40, 40)
    mask = disc_window_mask(disc, x0, y0, x1, y1)
    assert mask[10 - y0, 13 - x0] and mask[7 - y0, 10 - x0]
    assert not mask[8 - y0, 13 - x0]  # sqrt(13) > 3
    assert int(mask.sum()) == 29  # the lattice points within a radius of 3


def test_disc_bounds_clip_to_the_image() -> None:
    assert disc_bounds(Disc(1.0, 1.0, 5.0), 20, 10) == (0, 0, 7, 7)
    assert disc_bounds(Disc(19.0, 9.0, 5.0), 20, 10) == (14, 4, 20, 10)
    x0, y0, x1, y1 = disc_bounds(Disc(-10.0, 5.0, 2.0), 20, 10)
    assert x1 <= x0  # wholly outside: an empty window
