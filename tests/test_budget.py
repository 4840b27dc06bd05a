"""The time budget binds inside the monitoring stage (hostile case 3): MC dropout runs in chunks of the
same draw, the clock is read between chunks and between candidates, and memory stays at one chunk."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import TINY_ARCH, FakeClock, OracleSegmenter, scene_ids, scene_image

from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.monitors.mc_chunks import MC_CHUNK, Chunking, mc_samples
from el.segmentation import Segmenter
from el.segmentation.architectures import build_model

WW = 128
pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def seg():
    """The tiny CNN on patches (and MC dropout); frames segmented perfectly, so there are candidates."""
    torch.manual_seed(0)
    s = Segmenter(build_model(TINY_ARCH), working_width=WW, labels=UAVID)
    s.predict_frame = OracleSegmenter(WW).predict_frame
    return s


def test_chunks_of_one_draw_are_the_draw(seg):
    """Chunked samples equal the one-batch draw (masks drawn sample by sample: any chunk is its slice),
    whatever the chunk size; draws of at most MC_CHUNK samples are the one call, byte for byte."""
    rng = np.random.default_rng(0)
    patch = rng.integers(0, 255, (40, 56, 3), dtype=np.uint8)
    window = (3, 37, 5, 50)
    whole = seg.mc_dropout(patch, 45, 0.5, 7, window=window)
    for chunk in (1, 7, 16, 44):
        parts = mc_samples(seg, patch, 45, 0.5, 7, window=window, chunking=Chunking(chunk=chunk))
        np.testing.assert_allclose(parts, whole, rtol=0, atol=1e-6)
    # prefix-consistent: the first 20 of a chunked 45 are the chunked 20
    by8 = Chunking(chunk=8)
    np.testing.assert_allclose(mc_samples(seg, patch, 45, 0.5, 7, window=window, chunking=by8)[:20],
                               mc_samples(seg, patch, 20, 0.5, 7, window=window, chunking=by8), rtol=0, atol=1e-6)
    small = mc_samples(seg, patch, MC_CHUNK, 0.5, 7, window=window)
    assert np.array_equal(small, seg.mc_dropout(patch, MC_CHUNK, 0.5, 7, window=window))
    assert not np.allclose(mc_samples(seg, patch, 45, 0.5, 8, window=window), whole)  # the seed matters


def test_decisions_that_fit_the_budget_are_unchanged(seg):
    """Shipped configurations (n <= 30) decide as with one batch: the same candidates' verdicts."""
    image = scene_image(scene_ids())
    cfg = dict(core=CoreConfig(working_width=WW), monitor="lhd+ch+mcd:tau=0.25,n=30,rho=0.5", evaluate_all=True)
    with_budget = EmergencyLanding(PipelineConfig(**cfg, time_budget_s=1000.0), segmenter=seg).decide(image)
    without = EmergencyLanding(PipelineConfig(**cfg, time_budget_s=None), segmenter=seg).decide(image)
    assert len(without.candidates) >= 2
    assert with_budget.reason == without.reason and with_budget.selected == without.selected
    assert [c.monitor.reason for c in with_budget.candidates] == [c.monitor.reason for c in without.candidates]


@pytest.mark.requirements("EL-R07")
def test_a_huge_mc_draw_ends_in_timeout_within_budget_plus_ten_percent(seg):
    """Hostile case 3: 'lhd+ch+mcd:tau=0.25,n=1000,rho=0.5' with a 10 s budget. Each chunk of MC samples
    costs 1 s on the injected clock: the walk stops between chunks, before the budget is spent, and
    the drone takes the default action with reason 'timeout' (before: one 1000-sample batch, 43 s)."""
    clock = FakeClock()
    calls = []
    real = seg.model.head_logits

    def slow(features, mc=None):
        if mc is not None:
            calls.append(int(mc.masks[0].shape[0]))
            clock.t += 1.0
        return real(features, mc)

    seg.model.head_logits = slow
    try:
        cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd+ch+mcd:tau=0.25,n=1000,rho=0.5",
                             time_budget_s=10.0)
        d = EmergencyLanding(cfg, segmenter=seg, clock=clock).decide(scene_image(scene_ids()))
    finally:
        seg.model.head_logits = real
    assert (d.action, d.reason) == ("default", "timeout")
    assert d.timings["total_s"] <= 10.0 * 1.1
    assert 5 <= len(calls) <= 11 and max(calls) <= MC_CHUNK  # stopped after about 10 chunks of <= 32
