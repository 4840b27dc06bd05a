"""Segmentation network and inference API: shapes, determinism, MC dropout, weights hashing."""

from __future__ import annotations

import doctest
import json

import cv2
import numpy as np
import pytest
import torch
from helpers import TINY_ARCH as TINY
from torch import nn

import el.segmentation.inference as inference_module
from assurance.fitting.network.weights_io import save_weights, state_dict_bytes
from el.classes.labels import NUM_CLASSES, UAVID
from el.segmentation import (
    ArchConfig,
    Segmenter,
    WeightsError,
    build_model,
    load_weights,
)
from el.segmentation.model import MCSpec, count_parameters
from el.segmentation.protocol import FrameOptions
from el.segmentation.weights import card_path, read_card, sha256_file


@pytest.fixture(autouse=True, scope="module")
def _one_thread(one_torch_thread):
    """Every test here runs with one torch thread (conftest.one_torch_thread)."""


@pytest.fixture(scope="module")
def model() -> nn.Module:
    torch.manual_seed(0)
    m = build_model(TINY)
    # Non-trivial BatchNorm statistics, so that eval-mode BN differs from train-mode BN.
    m.train()
    with torch.no_grad():
        for _ in range(3):
            m(torch.rand(2, 3, 40, 48))
    return m.eval()


@pytest.fixture(scope="module")
def seg(model: nn.Module) -> Segmenter:
    return Segmenter(model, working_width=64, labels=UAVID)


def _rgb(h: int, w: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


# -- model contract ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("h", "w"), [(16, 16), (17, 23), (33, 50), (64, 40)])
def test_forward_gives_logits_at_input_size(model: nn.Module, h: int, w: int) -> None:
    with torch.inference_mode():
        out = model(torch.rand(2, 3, h, w))
    assert out.shape == (2, NUM_CLASSES, h, w)
    assert torch.isfinite(out).all()


def test_trunk_then_head_is_forward(model: nn.Module) -> None:
    x = torch.rand(1, 3, 37, 29)
    with torch.inference_mode():
        assert torch.equal(model.head(model.trunk(x)), model(x))


def test_default_architecture_is_compact() -> None:
    m = build_model()
    params = count_parameters(m)
    assert 200_000 <= params <= 1_000_000
    assert len(state_dict_bytes(m)) < 5_000_000
    assert len(m.dropout_layers()) >= 2


def test_arch_config_validates_and_round_trips() -> None:
    assert ArchConfig.from_dict(TINY.to_dict()) == TINY
    with pytest.raises(ValueError, match="dropout"):
        ArchConfig(dropout=1.0)
    with pytest.raises(ValueError, match="unknown architecture fields"):
        ArchConfig.from_dict({**TINY.to_dict(), "depth": 3})
    with pytest.raises(ValueError, match="drop probability"):
        build_model(TINY).set_dropout(1.5)


def test_set_dropout_changes_training_noise() -> None:
    m = build_model(TINY).train()
    m.set_dropout(0.0)
    x = torch.rand(1, 3, 32, 32)
    torch.manual_seed(1)
    a = m(x)
    torch.manual_seed(2)
    b = m(x)
    assert torch.allclose(a, b)  # same BN batch statistics, no dropout
    m.set_dropout(0.5)
    assert all(d.p == 0.5 for d in m.dropout_layers())


# -- Segmenter predictions ---------------------------------------------------------------------------
@pytest.mark.parametrize(("h", "w"), [(16, 16), (21, 37), (50, 33)])
def test_predict_patch_shape_and_softmax(seg: Segmenter, h: int, w: int) -> None:
    probs = seg.predict_patch(_rgb(h, w))
    assert probs.shape == (NUM_CLASSES, h, w) and probs.dtype == np.float32
    np.testing.assert_allclose(probs.sum(0), 1.0, atol=1e-5)
    assert (probs >= 0).all()


def test_predict_frame_resizes_to_working_resolution(seg: Segmenter) -> None:
    probs = seg.predict_frame(_rgb(72, 128))
    assert probs.shape == (NUM_CLASSES, 36, 64)
    odd = seg.predict_frame(_rgb(91, 150))  # working size (64, round(64 * 91 / 150) = 39)
    assert odd.shape == (NUM_CLASSES, 39, 64)


def test_predict_frame_at_working_size_equals_patch(seg: Segmenter) -> None:
    rgb = _rgb(36, 64)
    np.testing.assert_array_equal(seg.predict_frame(rgb), seg.predict_patch(rgb))


def test_frame_flip_averages_the_frame_and_its_mirror(model: nn.Module, seg: Segmenter) -> None:
    flip = Segmenter(model, working_width=64, frames=FrameOptions(frame_flip=True), labels=UAVID)
    rgb = _rgb(36, 64, seed=5)
    mirror = np.ascontiguousarray(rgb[:, ::-1])
    expected = 0.5 * (seg.predict_frame(rgb) + seg.predict_frame(mirror)[:, :, ::-1])
    got = flip.predict_frame(rgb)
    assert got.shape == (NUM_CLASSES, 36, 64) and got.dtype == np.float32 and got.flags.c_contiguous
    np.testing.assert_allclose(got, expected, atol=1e-6)
    assert np.abs(got - seg.predict_frame(rgb)).max() > 1e-4  # the untrained net is not mirror-symmetric
    # the averaged map is mirror-equivariant: the mirror image gets the mirrored map
    np.testing.assert_allclose(flip.predict_frame(mirror)[:, :, ::-1], got, atol=1e-6)
    np.testing.assert_array_equal(flip.predict_patch(rgb), seg.predict_patch(rgb))  # patches: unaffected
    with pytest.raises(ValueError, match="frame_flip"):
        Segmenter(model, frames=FrameOptions(frame_flip="yes"), labels=UAVID)


def test_frame_scales_feed_the_working_frame_resized_and_average(model: nn.Module, seg: Segmenter) -> None:
    rgb = _rgb(36, 64, seed=6)
    up = Segmenter(model, working_width=64, frames=FrameOptions(frame_scales=(1.5,)), labels=UAVID)
    big = seg.predict_patch(cv2.resize(rgb, (96, 54), interpolation=cv2.INTER_LINEAR))  # the network at x1.5
    expected = np.stack([cv2.resize(c, (64, 36), interpolation=cv2.INTER_AREA) for c in big])
    got = up.predict_frame(rgb)
    assert got.shape == (NUM_CLASSES, 36, 64) and got.dtype == np.float32 and got.flags.c_contiguous
    np.testing.assert_allclose(got, expected, atol=1e-6)
    np.testing.assert_allclose(got.sum(0), 1.0, atol=1e-5)  # still a softmax at the working resolution
    assert np.abs(got - seg.predict_frame(rgb)).max() > 1e-4
    both = Segmenter(model, working_width=64, frames=FrameOptions(frame_scales=[1, 1.5]), labels=UAVID)
    assert both.frame_scales == (1.0, 1.5)
    np.testing.assert_allclose(both.predict_frame(rgb), 0.5 * (seg.predict_frame(rgb) + got), atol=1e-6)
    # with the mirror image too: each size's pair is averaged
    flip_up = Segmenter(model, working_width=64, frames=FrameOptions(frame_scales=(1.5,), frame_flip=True),
                        labels=UAVID)
    mirror = np.ascontiguousarray(rgb[:, ::-1])
    np.testing.assert_allclose(flip_up.predict_frame(rgb), 0.5 * (got + up.predict_frame(mirror)[:, :, ::-1]),
                               atol=1e-6)
    np.testing.assert_array_equal(up.predict_patch(rgb), seg.predict_patch(rgb))  # patches: unaffected
    for bad in ((), (1.0, 1.0), (3.0,), (0.75,), (float("nan"),), "1.25", 1.25, (1, 1.1, 1.2, 1.3, 1.4), ("1.25",),
                (True,), None):
        with pytest.raises(ValueError, match="frame_scales"):
            Segmenter(model, frames=FrameOptions(frame_scales=bad), labels=UAVID)


def test_conservative_frame_pooling_keeps_what_a_source_pixel_shows(model: nn.Module, seg: Segmenter) -> None:
    from el.monitors.lhd import forbidden_pixels
    from el.segmentation.pooling import downsample_probs

    rgb = _rgb(36, 64, seed=7)
    cons = Segmenter(model, working_width=64, frames=FrameOptions(frame_scales=(1.5,), frame_pooling="conservative"),
                     labels=UAVID)
    big = seg.predict_patch(cv2.resize(rgb, (96, 54), interpolation=cv2.INTER_LINEAR))
    got = cons.predict_frame(rgb)
    np.testing.assert_allclose(got, downsample_probs(big, (64, 36), "conservative", labels=UAVID), atol=1e-6)
    area = Segmenter(model, working_width=64, frames=FrameOptions(frame_scales=(1.5,)), labels=UAVID).predict_frame(rgb)
    assert forbidden_pixels(got, labels=UAVID).sum() >= forbidden_pixels(area, labels=UAVID).sum()
    assert (forbidden_pixels(got, labels=UAVID) | ~forbidden_pixels(area, labels=UAVID)).all()  # stay forbidden
    with pytest.raises(ValueError, match="frame_pooling"):
        Segmenter(model, frames=FrameOptions(frame_pooling="max"), labels=UAVID)


def test_load_follows_the_cards_way_of_segmenting_frames(tmp_path, model: nn.Module) -> None:
    path = tmp_path / "model.pt"
    save_weights(model, path, card={"evaluation": {"protocol": {"frame_flip": True, "frame_scales": [1, 1.25],
                                                                "frame_pooling": "conservative"}}})
    loaded = Segmenter.load(path)
    assert loaded.frame_flip is True and loaded.frame_scales == (1.0, 1.25)
    assert loaded.frame_pooling == "conservative"
    save_weights(model, path, card={"evaluation": {"protocol": {"working_width": 1024}}})  # an older card
    loaded = Segmenter.load(path)
    assert loaded.frame_flip is False and loaded.frame_scales == (1.0,) and loaded.frame_pooling == "area"
    save_weights(model, path, card={"evaluation": {"protocol": {"frame_scales": [9]}}})
    with pytest.raises(ValueError, match="frame_scales"):
        Segmenter.load(path)


def test_eval_mode_is_deterministic(seg: Segmenter) -> None:
    rgb = _rgb(40, 40, seed=3)
    np.testing.assert_array_equal(seg.predict_patch(rgb), seg.predict_patch(rgb))


def test_predict_patches_keeps_order_and_batches(seg: Segmenter) -> None:
    patches = [_rgb(24, 24, 1), _rgb(32, 20, 2), _rgb(24, 24, 3)]
    out = seg.predict_patches(patches)
    assert [o.shape for o in out] == [(NUM_CLASSES, 24, 24), (NUM_CLASSES, 32, 20), (NUM_CLASSES, 24, 24)]
    for o, p in zip(out, patches, strict=True):
        np.testing.assert_allclose(o, seg.predict_patch(p), atol=1e-5)


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (np.zeros((32, 32, 3), np.float32), "uint8"),
        (np.zeros((32, 32), np.uint8), "shape"),
        (np.zeros((32, 32, 4), np.uint8), "shape"),
        (np.zeros((8, 32, 3), np.uint8), "too small"),
        ([[0, 0, 0]], "numpy array"),
    ],
)
def test_bad_inputs_raise_value_error(seg: Segmenter, bad: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        seg.predict_patch(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=match):
        seg.mc_dropout(bad, 2, 0.5, 0)  # type: ignore[arg-type]


class _NaNModel(nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = torch.zeros(x.shape[0], NUM_CLASSES, x.shape[2], x.shape[3])
        out[:, :, 0, 0] = float("nan")
        return out


class _WrongShape(nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.zeros(x.shape[0], 3, x.shape[2], x.shape[3])


def test_non_finite_output_raises() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        Segmenter(_NaNModel(), labels=UAVID).predict_patch(_rgb(20, 20))


def test_wrong_output_shape_raises() -> None:
    with pytest.raises(ValueError, match="expected logits of shape"):
        Segmenter(_WrongShape(), labels=UAVID).predict_patch(_rgb(20, 20))


def test_segmenter_rejects_bad_arguments(model: nn.Module) -> None:
    with pytest.raises(ValueError, match="torch.nn.Module"):
        Segmenter(object(), labels=UAVID)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="threads"):
        Segmenter(model, threads=0, labels=UAVID)


# -- Monte-Carlo dropout -------------------------------------------------------------------------------
def test_mc_dropout_shape_and_variability(seg: Segmenter) -> None:
    rgb = _rgb(40, 48)
    samples = seg.mc_dropout(rgb, 6, 0.5, seed=0)
    assert samples.shape == (6, NUM_CLASSES, 40, 48) and samples.dtype == np.float32
    np.testing.assert_allclose(samples.sum(1), 1.0, atol=1e-5)
    mean, std = samples.mean(axis=0), samples.std(axis=0)
    assert mean.shape == std.shape == (NUM_CLASSES, 40, 48)
    assert std.max() > 1e-4


def test_mc_dropout_keep_prob_one_has_zero_std(seg: Segmenter) -> None:
    rgb = _rgb(40, 48)
    samples = seg.mc_dropout(rgb, 5, 1.0, seed=0)
    assert samples.std(axis=0, dtype=np.float64).max() == 0.0
    np.testing.assert_array_equal(samples[0], seg.predict_patch(rgb))


def test_mc_dropout_reproducible_and_seed_dependent(seg: Segmenter) -> None:
    rgb = _rgb(33, 35)
    a = seg.mc_dropout(rgb, 4, 0.75, seed=7)
    np.testing.assert_array_equal(a, seg.mc_dropout(rgb, 4, 0.75, seed=7))
    assert not np.array_equal(a, seg.mc_dropout(rgb, 4, 0.75, seed=8))


def test_mc_dropout_is_prefix_consistent(seg: Segmenter) -> None:
    rgb = _rgb(32, 32)
    np.testing.assert_allclose(seg.mc_dropout(rgb, 3, 0.5, 11), seg.mc_dropout(rgb, 8, 0.5, 11)[:3], atol=1e-6)


def test_a_shared_trunk_gives_the_same_scores(seg: Segmenter) -> None:
    """predict_patch / mc_dropout with features=patch_trunk(rgb) equal the calls that run the trunk."""
    rgb = _rgb(37, 41)  # not a multiple of 8: the crop path too
    trunk = seg.patch_trunk(rgb)
    np.testing.assert_array_equal(seg.predict_patch(rgb, features=trunk), seg.predict_patch(rgb))
    for keep in (0.5, 1.0):
        np.testing.assert_array_equal(seg.mc_dropout(rgb, 5, keep, 3, features=trunk), seg.mc_dropout(rgb, 5, keep, 3))
    assert Segmenter(_PlainNet(), labels=UAVID).patch_trunk(rgb) is None  # no trunk/head split: nothing to share


@pytest.mark.parametrize("window", [(0, 37, 0, 41), (5, 30, 9, 26), (36, 37, 0, 1), (1, 37, 40, 41)])
def test_mc_dropout_window_is_the_slice_of_the_full_samples(seg: Segmenter, window) -> None:
    rgb = _rgb(37, 41)
    y0, y1, x0, x1 = window
    full = seg.mc_dropout(rgb, 4, 0.5, 9)
    got = seg.mc_dropout(rgb, 4, 0.5, 9, window=window, features=seg.patch_trunk(rgb))
    assert got.shape == (4, NUM_CLASSES, y1 - y0, x1 - x0)
    np.testing.assert_allclose(got, full[:, :, y0:y1, x0:x1], atol=1e-6)
    plain = Segmenter(_PlainNet(), labels=UAVID)  # the fallback path slices
    np.testing.assert_array_equal(plain.mc_dropout(rgb, 2, 0.5, 1, window=window),
                                  plain.mc_dropout(rgb, 2, 0.5, 1)[:, :, y0:y1, x0:x1])
    with pytest.raises(ValueError, match="window"):
        seg.mc_dropout(rgb, 2, 0.5, 1, window=(5, 5, 0, 3))


def test_mc_dropout_leaves_global_rng_and_bn_alone(seg: Segmenter, model: nn.Module) -> None:
    rng_state = torch.get_rng_state()
    buffers = {k: v.clone() for k, v in model.state_dict().items()}
    seg.mc_dropout(_rgb(32, 32), 4, 0.5, seed=1)
    assert torch.equal(rng_state, torch.get_rng_state())
    assert not model.training
    for k, v in model.state_dict().items():
        assert torch.equal(v, buffers[k]), k


def test_trunk_once_batch_equals_separate_passes(model: nn.Module) -> None:
    """The batched head gives each sample what a full forward pass with the same masks gives."""
    x = torch.rand(1, 3, 30, 26)
    n = 5
    spec = model.mc_spec(n, 0.5, seed=3)
    with torch.inference_mode():
        batched = model.head(model.trunk(x).repeat(n), spec)
        for i in range(n):
            single = model.head(model.trunk(x), MCSpec([m[i:i + 1] for m in spec.masks]))
            torch.testing.assert_close(batched[i:i + 1], single, atol=1e-5, rtol=1e-5)
    masks = spec.masks[0].flatten(1)
    assert set(torch.unique(masks).tolist()) <= {0.0, 2.0}  # kept channels scaled by 1 / keep_prob
    assert not all(torch.equal(masks[0], masks[i]) for i in range(1, n))


def test_mc_dropout_validation(seg: Segmenter) -> None:
    for n, keep in [(0, 0.5), (2, 0.0), (2, 1.5), (True, 0.5)]:
        with pytest.raises(ValueError):
            seg.mc_dropout(_rgb(20, 20), n, keep, 0)
    with pytest.raises(ValueError, match="seed"):
        seg.mc_dropout(_rgb(20, 20), 2, 0.5, 1.5)  # type: ignore[arg-type]


class _PlainNet(nn.Module):
    """Any module with the contract: MC dropout falls back to N passes with its dropout layers on."""

    def __init__(self) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(3, 8, 3, padding=1)
        self.bn = nn.BatchNorm2d(8)
        self.drop = nn.Dropout2d(0.1)
        self.conv2 = nn.Conv2d(8, NUM_CLASSES, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv2(self.drop(torch.relu(self.bn(self.conv1(x)))))


def test_plugged_in_module_mc_fallback() -> None:
    torch.manual_seed(0)
    net = _PlainNet()
    seg = Segmenter(net, labels=UAVID)
    assert not seg.fast_mc
    rgb = _rgb(24, 24)
    a = seg.mc_dropout(rgb, 4, 0.5, seed=2)
    assert a.shape == (4, NUM_CLASSES, 24, 24)
    assert a.std(axis=0).max() > 0
    np.testing.assert_array_equal(a, seg.mc_dropout(rgb, 4, 0.5, seed=2))
    np.testing.assert_allclose(a[:2], seg.mc_dropout(rgb, 2, 0.5, seed=2), atol=1e-6)
    assert net.drop.p == 0.1 and not net.drop.training and not net.bn.training  # restored / untouched


def test_mc_fallback_without_dropout_layers_raises() -> None:
    net = nn.Conv2d(3, NUM_CLASSES, 1)
    with pytest.raises(ValueError, match="no dropout layers"):
        Segmenter(net, labels=UAVID).mc_dropout(_rgb(20, 20), 3, 0.5, 0)


# -- weights and model cards ---------------------------------------------------------------------------
def test_weights_round_trip(tmp_path, model: nn.Module) -> None:
    path = tmp_path / "model.pt"
    card = save_weights(model, path, card={"note": "test"})
    assert card["weights_sha256"] == sha256_file(path) == read_card(path)["weights_sha256"]
    assert card["architecture"] == TINY.to_dict() and card["note"] == "test"
    seg = Segmenter.load(path)
    assert seg.weights_sha256 == card["weights_sha256"]
    rgb = _rgb(30, 30)
    np.testing.assert_array_equal(Segmenter(model, labels=UAVID).predict_patch(rgb), seg.predict_patch(rgb))


def test_tampered_weights_raise(tmp_path, model: nn.Module) -> None:
    path = tmp_path / "model.pt"
    save_weights(model, path)
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(WeightsError, match="SHA-256 mismatch") as exc:
        Segmenter.load(path)
    assert str(path) in str(exc.value)


def test_missing_weights_or_card_raise(tmp_path, model: nn.Module) -> None:
    with pytest.raises(WeightsError, match="not found"):
        Segmenter.load(tmp_path / "nope.pt")
    path = tmp_path / "model.pt"
    save_weights(model, path)
    card_path(path).unlink()
    with pytest.raises(WeightsError, match="model card not found"):
        load_weights(path)
    card_path(path).write_text("{not json")
    with pytest.raises(WeightsError, match="unreadable model card"):
        load_weights(path)
    card_path(path).write_text(json.dumps({"format": "other"}))
    with pytest.raises(WeightsError, match="format"):
        load_weights(path)


class _Evil:
    def __reduce__(self):  # pragma: no cover - never called when loading with weights_only
        return (print, ("code ran",))


def test_weights_only_refuses_pickled_objects(tmp_path, model: nn.Module) -> None:
    """Even with a matching hash, a file holding arbitrary objects is refused (weights_only)."""
    path = tmp_path / "model.pt"
    card = save_weights(model, path)
    torch.save({"payload": _Evil()}, path)
    card["weights_sha256"] = sha256_file(path)
    card_path(path).write_text(json.dumps(card))
    with pytest.raises(WeightsError, match="weights_only"):
        load_weights(path)


def test_state_dict_of_another_architecture_raises(tmp_path, model: nn.Module) -> None:
    path = tmp_path / "model.pt"
    card = save_weights(model, path)
    card["architecture"] = ArchConfig(widths=(8, 8, 24), ms_channels=8, decoder_channels=8).to_dict()
    card_path(path).write_text(json.dumps(card))
    with pytest.raises(WeightsError, match="does not fit"):
        load_weights(path)


def test_segmenter_pickles(seg: Segmenter) -> None:
    import pickle

    clone = pickle.loads(pickle.dumps(seg))
    rgb = _rgb(24, 24)
    np.testing.assert_array_equal(clone.predict_patch(rgb), seg.predict_patch(rgb))
    np.testing.assert_array_equal(clone.mc_dropout(rgb, 3, 0.5, 1), seg.mc_dropout(rgb, 3, 0.5, 1))


def test_docstring_examples() -> None:
    result = doctest.testmod(inference_module, optionflags=doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted > 0
