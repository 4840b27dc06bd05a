"""Every candidate of a frame judged at once (``Monitor.check_many``) gives the verdicts of one ``check`` per
candidate: the patches' softmax batched by padded size or spread over single-threaded ONNX Runtime sessions,
the same scores; the score walk's batch judge; the PNG fast path of the frame reader."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import TINY_ARCH, OracleSegmenter, scene_ids, scene_image

from el.base.decision import Candidate
from el.base.errors import DataError
from el.base.hashing import sha256_file
from el.base.imageio import read_image, read_image_hashed
from el.classes.labels import UAVID
from el.flight.pipeline import DEPLOYED_MONITOR, EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.monitors import CandidateContext, build_monitor
from el.monitors.learned import LearnedMonitor, load_learned_model
from el.monitors.lhd import LHDMonitor
from el.monitors.patch_judge import batch_judge
from el.monitors.walk import SCORE
from el.segmentation.architectures import build_model
from el.segmentation.batching import group_by_padded_size, pad_edge, padded_size, padding_multiple
from el.segmentation.inference import Segmenter
from el.segmentation.patch_pool import PatchPool

WW = 64
NET = load_learned_model(labels=UAVID).network_sha256  # the network the shipped learned model was fitted on
RNG = np.random.default_rng(7)
FRAME = RNG.integers(0, 255, (144, 256, 3), dtype=np.uint8)
# radii 10..20 px: patches of 27..51 px a side, several sharing a padded size; the first is cut by the border
CANDIDATES = [Candidate(k, x, y, r, 0.1 * k, 0.1 * k, 0.0) for k, (x, y, r) in enumerate(
    [(4.5, 70.2, 12.0), (60.5, 40.5, 10.0), (120.3, 90.7, 10.4), (200.0, 60.0, 20.0), (150.5, 120.5, 13.0)])]


@pytest.fixture(scope="module")
def segmenters(tmp_path_factory):
    """The tiny network under torch and under ONNX Runtime, both reporting the learned model's network."""
    pytest.importorskip("onnxruntime")
    import torch

    from assurance.fitting.network.onnx_export import export_onnx
    from el.base.hashing import sha256_file
    from el.segmentation.onnx_engine import OnnxEngine

    torch.manual_seed(0)
    native = Segmenter(build_model(TINY_ARCH), working_width=WW, card={"weights_sha256": NET}, labels=UAVID)
    path = tmp_path_factory.mktemp("tiny") / "tiny.onnx"
    export_onnx(native, path, frame=FRAME)
    engine = OnnxEngine(path, sha256_file(path), threads=2)
    return native, Segmenter(native.model, working_width=WW, card={"weights_sha256": NET}, engine=engine, labels=UAVID)


def _contexts(seg, candidates=CANDIDATES, frame=FRAME):
    probs = seg.predict_frame(frame)
    return [CandidateContext(c, probs, (frame.shape[1], frame.shape[0])) for c in candidates]


def test_padding_helpers():
    assert padded_size((27, 33), 8) == (32, 40) and padded_size((32, 40), 8) == (32, 40)
    assert group_by_padded_size([(27, 27), (31, 29), (40, 33), (25, 30)], 8) == {(32, 32): [0, 1, 3], (40, 40): [2]}
    rgb = RNG.integers(0, 255, (5, 3, 3), dtype=np.uint8)
    padded = pad_edge(rgb, (8, 8))
    assert padded.shape == (8, 8, 3) and (padded[:5, :3] == rgb).all() and (padded[7, 7] == rgb[4, 2]).all()
    assert padding_multiple(build_model(TINY_ARCH)) == 8 and padding_multiple(object()) == 1


@pytest.mark.parametrize("mode", ["torch", "onnx batched", "onnx pool"])
def test_predict_patches_gives_each_patch_its_lone_scores(segmenters, mode):
    native, onnx = segmenters
    seg = native if mode == "torch" else onnx
    seg.patch_workers = 2 if mode == "onnx pool" else 1
    patches = [np.ascontiguousarray(FRAME[y:y + h, x:x + w])
               for x, y, h, w in ((0, 0, 27, 27), (30, 5, 31, 29), (60, 40, 40, 33), (100, 90, 27, 27),
                                  (150, 20, 17, 50))]
    many = seg.predict_patches(patches)
    for p, m in zip(patches, many, strict=True):
        lone = seg.predict_patch(p)
        assert m.shape == lone.shape and m.dtype == np.float32 and m.flags["C_CONTIGUOUS"]
        if mode == "torch":  # a torch batch may round differently in the last bits
            np.testing.assert_allclose(m, lone, atol=1e-6)
        else:
            np.testing.assert_array_equal(m, lone)


@pytest.mark.parametrize("mode", ["torch", "onnx batched", "onnx pool"])
@pytest.mark.parametrize("kind", ["learned", "lhd"])
def test_check_many_gives_the_verdicts_of_check(segmenters, mode, kind):
    native, onnx = segmenters
    seg = native if mode == "torch" else onnx
    seg.patch_workers = 2 if mode == "onnx pool" else 1
    monitor = LearnedMonitor(labels=UAVID) if kind == "learned" else LHDMonitor(labels=UAVID)
    contexts = _contexts(seg)
    seeds = [3 + k for k in range(len(CANDIDATES))]
    lone = [monitor.check(FRAME, c, seg, seed=s, context=x)
            for c, s, x in zip(CANDIDATES, seeds, contexts, strict=True)]
    many = monitor.check_many(FRAME, CANDIDATES, seg, seeds=seeds, contexts=contexts)
    assert monitor.batches_softmax() == (kind == "learned") and len(many) == len(lone)  # LHD: one at a time
    for a, b in zip(lone, many, strict=True):
        assert (a.name, a.accepted, a.threshold) == (b.name, b.accepted, b.threshold) and b.seconds >= 0
        if mode == "torch":
            assert b.score == pytest.approx(a.score, abs=1e-6)
        else:
            assert (a.score, a.reason) == (b.score, b.reason)


class Counting(OracleSegmenter):
    """The oracle, counting batched calls and posing as the network the learned model was fitted on."""

    weights_sha256 = NET

    def __init__(self, working_width):
        super().__init__(working_width)
        self.batches = 0

    def predict_patches(self, patches):
        self.batches += 1
        return [self.predict_patch(p) for p in patches]


def test_monitors_whose_features_are_not_the_softmax_are_judged_one_at_a_time():
    seg = Counting(WW)
    frame = scene_image(scene_ids(256, 144, seed=1))
    mcd = build_monitor("lhd+mcd:n=3,rho=0.9", labels=UAVID)

    class OwnFeatures(LearnedMonitor):  # overrides patch_features alone: its features are not the learned ones
        def patch_features(self, patch, segmenter, **kw):
            return super().patch_features(patch, segmenter, **kw)

    assert LearnedMonitor(labels=UAVID).batches_softmax()
    assert not any(m.batches_softmax() for m in (mcd, OwnFeatures(labels=UAVID), LHDMonitor(labels=UAVID)))
    seeds = list(range(len(CANDIDATES)))
    contexts = _contexts(seg, frame=frame)
    for monitor, ctx in ((mcd, None), (OwnFeatures(labels=UAVID), contexts)):
        lone = [monitor.check(frame, c, seg, seed=s, context=None if ctx is None else ctx[k])
                for k, (c, s) in enumerate(zip(CANDIDATES, seeds, strict=True))]
        many = monitor.check_many(frame, CANDIDATES, seg, seeds=seeds, contexts=ctx)
        assert [(v.score, v.accepted) for v in lone] == [(v.score, v.accepted) for v in many]
    with pytest.raises(ValueError, match="5 candidates, 4 seeds"):
        LHDMonitor(labels=UAVID).check_many(frame, CANDIDATES, seg, seeds=seeds[:4])


def test_batch_judge_judges_the_frame_once_and_only_that_frame():
    seg = Counting(WW)
    monitor = LearnedMonitor(labels=UAVID)
    contexts = _contexts(seg)
    judge = batch_judge(monitor, FRAME, CANDIDATES, seg, probs=contexts[0].frame_probs, seed=3)
    verdicts = [judge(k) for k in reversed(range(len(CANDIDATES)))][::-1]
    assert seg.batches == 1 and seg.patch_calls == len(CANDIDATES)
    lone = [monitor.check(FRAME, c, seg, seed=3 + k, context=x)
            for k, (c, x) in enumerate(zip(CANDIDATES, contexts, strict=True))]
    assert [(v.score, v.accepted) for v in verdicts] == [(v.score, v.accepted) for v in lone]
    other = batch_judge(monitor, FRAME[::-1].copy(), CANDIDATES[:2], seg, probs=contexts[0].frame_probs, seed=3)
    assert other(1) is not verdicts[1] and seg.batches == 2  # a new frame's judge judges anew


class BatchedLanding(EmergencyLanding):
    """The flight loop with the score walk's batch judge and the hashing reader (the wiring ``EmergencyLanding``
    takes in ``_judge`` and ``_read``)."""

    def _read(self, image, info):
        if not isinstance(image, str | Path):
            return super()._read(image, info)
        info["path"] = str(image)
        rgb, meta, info["sha256"] = read_image_hashed(image, max_pixels=self.config.max_pixels)
        info.update(meta)
        info["width"], info["height"] = int(rgb.shape[1]), int(rgb.shape[0])
        return rgb

    def _judge(self, frame, budget):
        judge, before, after = super()._judge(frame, budget)
        if judge is None or self.walk != SCORE:
            return judge, before, after
        return batch_judge(self.monitor, frame.rgb, frame.candidates, self.segmenter, probs=frame.probs,
                           seed=self.config.seed), before, after


def test_batched_flight_decisions_are_the_per_candidate_ones(tmp_path):
    config = PipelineConfig(core=CoreConfig(working_width=WW), monitor=DEPLOYED_MONITOR, time_budget_s=None)
    for seed in range(3):
        frame = scene_image(scene_ids(256, 144, seed=seed, road_col=40 + 60 * seed))
        path = tmp_path / f"{seed}.png"
        cv2.imwrite(str(path), frame[:, :, ::-1])
        seg = Counting(WW)
        a = EmergencyLanding(config, segmenter=Counting(WW)).decide(path)
        b = BatchedLanding(config, segmenter=seg).decide(path)
        assert a.input == b.input and a.input["sha256"] == sha256_file(path)
        assert a.reason == b.reason and not a.reason.startswith("fault") and a.candidates
        assert (a.action, a.selected) == (b.action, b.selected) and seg.batches == 1
        assert [(c.x, c.y, c.monitor.score, c.monitor.accepted) for c in a.candidates] == \
               [(c.x, c.y, c.monitor.score, c.monitor.accepted) for c in b.candidates]


def test_patch_pool_keeps_order_and_raises_the_first_error():
    pool = PatchPool(lambda: object(), 2)
    assert pool.map([lambda e, i=i: i * i for i in range(7)], order=[6, 5, 4, 3, 2, 1, 0]) == [i * i for i in range(7)]

    def bad(engine):
        raise ValueError("patch 3 is broken")

    with pytest.raises(ValueError, match="patch 3"):
        pool.map([lambda e: 1, bad, lambda e: 2])
    with pytest.raises(ValueError, match="2 workers"):
        PatchPool(lambda: object(), 1)


def test_the_png_fast_path_reads_the_pixels_the_general_path_reads(tmp_path):
    rgb = RNG.integers(0, 255, (40, 50, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb[:, :, ::-1])
    got = read_image(tmp_path / "rgb.png")
    assert got.flags["C_CONTIGUOUS"] and got.dtype == np.uint8 and (got == rgb).all()
    rgba = np.dstack([rgb[:, :, ::-1], np.full((40, 50), 7, np.uint8)])
    cv2.imwrite(str(tmp_path / "rgba.png"), rgba)  # colour type 6: the general path, alpha dropped
    assert (read_image(tmp_path / "rgba.png") == rgb).all()
    cv2.imwrite(str(tmp_path / "grey.png"), rgb[:, :, 0])
    with pytest.raises(DataError, match="single-channel"):
        read_image(tmp_path / "grey.png")
    cv2.imwrite(str(tmp_path / "deep.png"), rgb.astype(np.uint16) * 257)
    with pytest.raises(DataError, match="8-bit"):
        read_image(tmp_path / "deep.png")
