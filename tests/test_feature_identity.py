"""The learned monitor's features, computed in one pass per patch and one window per frame (issue 52: the decision
faster, unchanged), give bit for bit the numbers of the per-feature reference helpers they replaced in
``candidate_features`` (kept in tests/feature_reference.py): every float64 of the vector, for any layout, dtype,
patch scale and disc size."""

from __future__ import annotations

import feature_reference as ref
import numpy as np
import pytest

from el.base.decision import Candidate, Disc
from el.classes.labels import UAVID
from el.geometry.discs import disc_window_mask, window_sq_distances
from el.landing.forbidden import forbidden_pixels
from el.monitors import learned
from el.monitors.base import CandidateContext
from el.monitors.lhd import take_disc
from el.monitors.patches import extract_patch

W, H, WW, WH = 384, 216, 128, 72  # full-resolution frame and working grid (scale 1/3)


def reference(patch_probs, patch, context, margin):
    """``candidate_features`` as it was computed before (one helper per feature group)."""
    frame, cand = context.frame_probs, context.candidate
    width, height = context.frame_size
    scale = frame.shape[2] / width
    lr = ref.frame_disc(frame, cand, scale)
    hd = take_disc(patch_probs, patch.disc_mask)
    return np.asarray([*ref.disc_stats(lr, UAVID), *ref.disc_stats(hd, UAVID),
                       ref.edge_distance(patch_probs, patch, cand, margin, UAVID),
                       cand.y / height, cand.radius_px / height, float(cand.hazard),
                       *ref.context_stats(frame, cand, scale, UAVID),
                       *ref.class_max(hd, UAVID), *ref.class_max(lr, UAVID)], dtype=np.float64)


def softmax(rng, shape, *, forbidden_share, dtype=np.float32, spread=2.0):
    """Softmax-like scores (C, h, w): random logits (standard deviation ``spread``: a wide one gives probabilities
    of very different magnitudes, whose float64 sums depend on the order they are added in), forbidden classes
    boosted on blobs covering about ``forbidden_share`` of the pixels (0: none wins anywhere)."""
    logits = rng.normal(0.0, spread, (8, *shape))
    fids = list(UAVID.forbidden_ids)
    if forbidden_share == 0:
        logits[fids] -= 50.0
    else:
        blobs = rng.random(shape) < forbidden_share
        logits[fids] += np.where(blobs, 6.0, -6.0)
    e = np.exp(logits - logits.max(axis=0))
    return (e / e.sum(axis=0)).astype(dtype)


def same_bits(a, b):
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def one_case(rng, *, x, y, r, margin=0.25, max_side=None, share=0.2, layout="c", dtype=np.float32, spread=2.0):
    cand = Candidate(0, x, y, r, float(rng.random()), 0.1, 0.1)
    patch = extract_patch(np.zeros((H, W, 3), np.uint8), cand, margin=margin, max_side=max_side)
    patch_probs = softmax(rng, patch.shape, forbidden_share=share, dtype=dtype, spread=spread)
    frame = softmax(rng, (WH, WW), forbidden_share=0.3, dtype=dtype, spread=spread)
    if layout == "channels_last":  # what a channels-last network returns: classes innermost in memory
        frame = np.moveaxis(np.ascontiguousarray(np.moveaxis(frame, 0, -1)), -1, 0)
        patch_probs = np.moveaxis(np.ascontiguousarray(np.moveaxis(patch_probs, 0, -1)), -1, 0)
    context = CandidateContext(cand, frame, (W, H))
    got = learned.candidate_features(patch_probs, patch, context, margin=margin, labels=UAVID)
    return got, reference(patch_probs, patch, context, margin)


@pytest.mark.parametrize("layout", ["c", "channels_last"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_features_are_the_reference_bit_for_bit(layout, dtype):
    rng = np.random.default_rng(52)
    for _ in range(40):
        got, want = one_case(rng, x=float(rng.uniform(0, W)), y=float(rng.uniform(0, H)),
                             r=float(rng.uniform(2.0, 60.0)), share=float(rng.choice([0.0, 0.01, 0.2, 0.9])),
                             layout=layout, dtype=dtype, spread=float(rng.choice([2.0, 25.0])))
        assert same_bits(got, want), (got - want)


def test_edge_cases_are_the_reference_bit_for_bit():
    rng = np.random.default_rng(7)
    cases = [
        {"x": 0.3, "y": 0.2, "r": 5.0},  # a corner: every window clipped
        {"x": W - 0.1, "y": H - 0.1, "r": 40.0},  # the opposite corner, a large disc
        {"x": 100.5, "y": 60.5, "r": 1.2},  # a disc smaller than a working pixel: the pixel under the centre
        {"x": 101.2, "y": 61.3, "r": 0.6},  # one full-resolution pixel, far below a working pixel
        {"x": 200.0, "y": 100.0, "r": 30.0, "share": 0.0},  # no forbidden pixel in the patch: the edge cap
        {"x": 200.0, "y": 100.0, "r": 30.0, "share": 1.0},  # forbidden everywhere: -1 radii
        {"x": 190.2, "y": 90.7, "r": 55.0, "max_side": 32},  # a downscaled patch (scale < 1)
        {"x": 50.0, "y": 150.0, "r": 12.0, "margin": 1.5},  # a wide context margin
    ]
    for case in cases:
        got, want = one_case(rng, **case)
        assert same_bits(got, want), (case, got - want)


def test_the_nearest_forbidden_pixel_is_the_reference_on_any_mask():
    rng = np.random.default_rng(11)
    for _ in range(200):
        disc = Disc(float(rng.uniform(20, 180)), float(rng.uniform(20, 180)), float(rng.uniform(1, 20)))
        patch = extract_patch(np.zeros((200, 200, 3), np.uint8), disc, max_side=int(rng.choice([16, 4096])))
        forbidden = rng.random(patch.shape) < rng.choice([0.0, 0.002, 0.05, 0.5])
        probs = np.zeros((8, *patch.shape), np.float32)
        probs[UAVID.forbidden_ids[0]] = forbidden
        probs[UAVID.safe_ids[0]] = ~forbidden
        want = ref.edge_distance(probs, patch, disc, 0.25, UAVID)
        assert learned.nearest_forbidden(forbidden_pixels(probs, UAVID), patch, disc, 0.25) == want


def test_one_grid_of_squared_distances_draws_every_disc_as_disc_window_mask_does():
    rng = np.random.default_rng(5)
    for _ in range(100):
        x, y = float(rng.uniform(-5, 60)), float(rng.uniform(-5, 60))
        x0, y0 = (int(v) for v in rng.integers(0, 30, 2))
        x1, y1 = x0 + int(rng.integers(1, 40)), y0 + int(rng.integers(1, 40))
        d2 = window_sq_distances(x, y, x0, y0, x1, y1)
        for r in rng.uniform(0.1, 30.0, 4):
            assert np.array_equal(d2 <= r * r, disc_window_mask(Disc(x, y, float(r)), x0, y0, x1, y1))


def test_a_non_finite_patch_or_frame_is_still_refused():
    rng = np.random.default_rng(1)
    cand = Candidate(0, 150.0, 90.0, 20.0, 0.1, 0.1, 0.1)
    patch = extract_patch(np.zeros((H, W, 3), np.uint8), cand)
    probs = softmax(rng, patch.shape, forbidden_share=0.1)
    frame = softmax(rng, (WH, WW), forbidden_share=0.1)
    probs[3, 2, 2] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        learned.candidate_features(probs, patch, CandidateContext(cand, frame, (W, H)), margin=0.25, labels=UAVID)
    frame[0, 30, 40] = np.inf
    probs[3, 2, 2] = 0.0
    with pytest.raises(ValueError, match="non-finite"):
        learned.candidate_features(probs, patch, CandidateContext(cand, frame, (W, H)), margin=0.25, labels=UAVID)
