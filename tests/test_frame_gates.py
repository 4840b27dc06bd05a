"""The frame gates: they read the segmentation pass's own trunk and logits (no second trunk pass),
and with a tiny network fitted on in-domain frames they flag constant, noise and severity-5 fog frames."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import tiny_scene

from assurance.perturbations import perturb
from el.classes.labels import UAVID, ids_to_colors
from el.monitors.gates import GATES
from el.segmentation.architectures import build_model
from el.segmentation.inference import Segmenter
from el.segmentation.model import ArchConfig

IN_DOMAIN = ("none", "brightness", "fog", "motion_blur", "shifted_pixels", "pixel_trap")


@pytest.fixture(scope="module")
def tiny():
    torch.manual_seed(0)
    return Segmenter(build_model(ArchConfig(widths=(8, 8, 8), decoder_channels=8)), working_width=128, labels=UAVID)


def _frames(seeds, rng_seed):
    rng = np.random.default_rng(rng_seed)
    out = []
    for i in seeds:
        rgb = ids_to_colors(tiny_scene(i))
        for p in IN_DOMAIN:
            out.append(rgb if p == "none" else perturb(rgb, p, int(rng.integers(1, 4)), np.random.default_rng(i)))
    return out


def _taps(seg, frames):
    return [seg.predict_frame(f, stats=True).stats for f in frames]


def test_the_frame_pass_taps_its_own_trunk_once(tiny, monkeypatch):
    rgb = ids_to_colors(tiny_scene(0))
    calls = []
    trunk = tiny.model.trunk
    monkeypatch.setattr(tiny.model, "trunk", lambda x: calls.append(1) or trunk(x))
    probs, tap = tiny.predict_frame(rgb, stats=True)
    assert len(calls) == 1 and tap.pooled is not None and np.isfinite(tap.energy)
    with torch.inference_mode():  # the same logits as the network's own forward pass
        ref = torch.softmax(tiny.model(tiny._to_tensor([rgb_working(tiny, rgb)])), 1)
    assert np.allclose(probs, ref[0].numpy(), atol=1e-6)


def test_the_statistics_come_back_with_the_frame_they_describe(tiny):
    """No side channel: ``predict_frame(rgb, stats=True)`` returns the statistics of that frame's own pass with its
    probabilities, the same probabilities as without them, and the model keeps nothing between calls (two frames
    segmented in either order give each its own statistics)."""
    a, b = ids_to_colors(tiny_scene(0)), ids_to_colors(tiny_scene(1))
    first, second = tiny.predict_frame(a, stats=True), tiny.predict_frame(b, stats=True)
    assert np.allclose(first.probs, tiny.predict_frame(a), atol=1e-6)
    assert first.stats.energy != second.stats.energy
    again = tiny.predict_frame(a, stats=True)  # after another frame: its own statistics, not the last frame's
    assert again.stats.energy == pytest.approx(first.stats.energy) and np.allclose(again.stats.pooled,
                                                                                   first.stats.pooled)
    assert not any("tap" in name for name in vars(tiny))


def rgb_working(seg, rgb):
    import cv2

    w, h = seg.working_size(rgb.shape[1], rgb.shape[0])
    return cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)


def _fit(name, train, val):
    gate = GATES[name]
    params = gate.fit(np.array([gate.embed(t) for t in train]))
    threshold = float(np.quantile(gate.score(params, np.array([gate.embed(t) for t in val])), 0.99))
    return lambda taps: gate.score(params, np.array([gate.embed(t) for t in taps])) > threshold


def test_a_gate_flags_constant_noise_and_fog5_frames(tiny):
    rng = np.random.default_rng(0)
    clean = ids_to_colors(tiny_scene(20))
    odd = {"constant": _taps(tiny, [np.full_like(clean, v) for v in (0, 90, 200, 255)]),
           "noise": _taps(tiny, [rng.integers(0, 256, clean.shape, dtype=np.uint8) for _ in range(4)])}
    fog5 = _taps(tiny, [perturb(ids_to_colors(tiny_scene(i)), "fog", 5, np.random.default_rng(i))
                        for i in range(20, 24)])
    # fitted with the in-domain perturbations (severities 1-3): constant and noise frames are flagged, held-out
    # in-domain frames pass; to this tiny random network fog 5 looks like the fog 1-3 it was fitted on
    flag = _fit("mahalanobis", _taps(tiny, _frames(range(0, 8), 1)), _taps(tiny, _frames(range(8, 12), 2)))
    for name, taps in odd.items():
        assert flag(taps).all(), name
    assert flag(_taps(tiny, _frames(range(12, 16), 3))).mean() <= 0.1
    # fitted on clean frames, the same gate flags fog 5 too (and every other perturbation: why it is fitted
    # with them, and why the declared domain, not the gate, says how far the evidence on thick fog reaches)
    flag = _fit("mahalanobis", _taps(tiny, [ids_to_colors(tiny_scene(i)) for i in range(24, 44)]),
                _taps(tiny, [ids_to_colors(tiny_scene(i)) for i in range(44, 50)]))
    assert flag(fog5).all() and flag(odd["constant"]).all() and flag(odd["noise"]).all()
    for other in ("energy", "knn"):  # every gate fits and scores behind the same interface
        assert _fit(other, odd["noise"] + fog5, odd["constant"])(fog5).dtype == bool


def test_a_gate_needing_the_trunk_refuses_a_logits_only_tap():
    from el.segmentation.frame_tap import FrameTap

    with pytest.raises(ValueError, match="logits only"):
        GATES["knn"].embed(FrameTap(energy=-1.0, msp=0.9))
    assert GATES["energy"].embed(FrameTap(energy=-1.0, msp=0.9)).tolist() == [-1.0]
