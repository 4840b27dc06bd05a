"""Bringing a softmax map down to the working resolution: conservative pooling keeps forbidden pixels."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from el.classes.labels import NUM_CLASSES, UAVID
from el.monitors.lhd import forbidden_pixels
from el.segmentation.pooling import downsample_probs


def _softmax(rng: np.random.Generator, h: int, w: int, spread: float) -> np.ndarray:
    logits = rng.normal(0, spread, (NUM_CLASSES, h, w)).astype(np.float32)
    e = np.exp(logits - logits.max(axis=0, keepdims=True))
    return e / e.sum(axis=0, keepdims=True)


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), h=st.integers(2, 24), w=st.integers(2, 24), fy=st.floats(0.3, 1.0),
       fx=st.floats(0.3, 1.0), spread=st.floats(0.1, 4.0))
def test_conservative_pooling_never_drops_a_forbidden_pixel(seed, h, w, fy, fx, spread) -> None:
    rng = np.random.default_rng(seed)
    probs = _softmax(rng, h, w, spread)
    oh, ow = max(1, int(h * fy)), max(1, int(w * fx))
    out = downsample_probs(probs, (ow, oh), "conservative", labels=UAVID)
    assert out.shape == (NUM_CLASSES, oh, ow)
    np.testing.assert_allclose(out.sum(axis=0), 1.0, atol=1e-5)
    src, dst = forbidden_pixels(probs, labels=UAVID), forbidden_pixels(out, labels=UAVID)
    for i in range(oh):  # every source pixel overlapping output pixel (i, j)
        r0, r1 = (i * h) // oh, -((-(i + 1) * h) // oh)
        for j in range(ow):
            c0, c1 = (j * w) // ow, -((-(j + 1) * w) // ow)
            if src[r0:r1, c0:c1].any():
                assert dst[i, j], (i, j)


def test_area_pooling_can_drop_a_thin_hazard_that_conservative_keeps() -> None:
    probs = np.zeros((NUM_CLASSES, 5, 5), np.float32)
    probs[5] = 0.9   # low vegetation
    probs[2] = 0.1
    probs[2, :, 2], probs[5, :, 2] = 0.6, 0.4  # a one-pixel-wide road, column 2
    area = downsample_probs(probs, (4, 4), "area", labels=UAVID)
    cons = downsample_probs(probs, (4, 4), "conservative", labels=UAVID)
    assert not forbidden_pixels(area, labels=UAVID).any()
    assert forbidden_pixels(cons, labels=UAVID)[:, 1:3].all()


def test_same_size_is_identity_for_conservative_and_bad_input_refused() -> None:
    probs = _softmax(np.random.default_rng(1), 6, 7, 1.0)
    np.testing.assert_allclose(downsample_probs(probs, (7, 6), "conservative", labels=UAVID), probs, atol=1e-6)
    with pytest.raises(ValueError, match="frame_pooling"):
        downsample_probs(probs, (3, 3), "max", labels=UAVID)
    with pytest.raises(ValueError, match="up to"):
        downsample_probs(probs, (9, 9), "conservative", labels=UAVID)
