"""Training, data preparation, checkpoints/resume, model-card verification and the CLI, on tiny data."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import TINY_ARCH

import assurance.cli as cli
from assurance.dataio.uavid import write_sample
from assurance.fitting.network import data as D
from assurance.fitting.network.card import verify_card
from assurance.fitting.network.checkpoint import checkpoint_path, load_checkpoint
from assurance.fitting.network.evaluation import compare_figures, confusion, summarise
from assurance.fitting.network.train_config import TrainConfig, steps_for_epochs
from assurance.fitting.network.training import (
    RunOptions,
    prefetched,
    resolve_device,
    sample_batch,
    train,
    training_loss,
)
from el.classes.labels import NUM_CLASSES, PALETTE, UAVID
from el.segmentation.architectures import build_model
from el.segmentation.inference import Segmenter
from el.segmentation.model import ArchConfig
from el.segmentation.protocol import EvalProtocol
from el.segmentation.weights import card_path, read_card

RESUME = RunOptions(resume=True)


@pytest.fixture(autouse=True, scope="module")
def _one_thread(one_torch_thread):
    """Every test here runs with one torch thread (conftest.one_torch_thread)."""


def tiny_config(**overrides) -> TrainConfig:
    base = dict(
        steps=6, batch=2, crop=32, hd_pixels=2 * 32 * 32, hd_crop_min=32, hd_crop_max=48, hd_regions=2,
        warmup=2, checkpoint_every=3, working_width=64, arch=TINY_ARCH, baseline_pixels=2000, lr=5e-3,
        eval_protocol=EvalProtocol(working_width=64, hd_patches=1, hd_patch_size=48),
    )
    base.update(overrides)
    return TrainConfig(**base)


def fake_scene(rng: np.random.Generator, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Rectangles of random classes on low vegetation, each class with its own colour and stripes."""
    ids = np.full((height, width), 5, np.uint8)
    for _ in range(int(rng.integers(3, 7))):
        k = int(rng.integers(0, NUM_CLASSES))
        h, w = int(rng.integers(height // 6, height // 2)), int(rng.integers(width // 6, width // 2))
        y, x = int(rng.integers(0, height - h)), int(rng.integers(0, width - w))
        ids[y:y + h, x:x + w] = k
    xx = np.arange(width)[None, :]
    texture = np.sin(xx * (0.3 + 0.1 * ids)) * 20
    img = PALETTE[ids] * 0.6 + 50 + texture[..., None] + rng.normal(0, 8, (height, width, 3))
    return np.clip(img, 0, 255).astype(np.uint8), ids


def fake_dataset(root: Path, n: int, *, seed: int, width: int = 128, height: int = 72) -> Path:
    rng = np.random.default_rng(seed)
    for i in range(n):
        write_sample(root, f"seq{i % 2 + 1:02d}", f"{i:06d}", *fake_scene(rng, width, height), labels=UAVID)
    return root


@pytest.fixture(scope="module")
def datasets(tmp_path_factory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("segdata")
    return fake_dataset(base / "train", 4, seed=1), fake_dataset(base / "val", 2, seed=2)


# -- data preparation ---------------------------------------------------------------------------------
def test_downsample_labels_takes_the_majority() -> None:
    ids = np.zeros((4, 8), np.uint8)
    ids[:, :3] = 2  # 3 of 4 columns of the left output pixel are road
    ids[0, 4:] = 7  # 1 of 4 rows of the right output pixel is a moving car
    out = D.downsample_labels(ids, (2, 1))
    assert out.tolist() == [[2, 0]]


def test_class_weights_are_balanced_and_bounded() -> None:
    freq = np.array([0.5, 0.3, 0.15, 0.04, 0.01, 0.0, 0.0, 0.0])
    w = D.class_weights(freq)
    assert w.shape == (NUM_CLASSES,) and np.isfinite(w).all()
    assert np.isclose((freq * w).sum(), 1.0)
    assert w[4] > w[3] > w[2] > w[1] > w[0]
    assert np.all(w[5:] == w[:5].max())


def test_patch_positions_are_seeded_and_reachable() -> None:
    a = D.patch_positions("seq01/000001", 3840, 2160, count=3, size=384, seed=5)
    assert a == D.patch_positions("seq01/000001", 3840, 2160, count=3, size=384, seed=5)
    assert a != D.patch_positions("seq01/000002", 3840, 2160, count=3, size=384, seed=5)
    side, corners = a
    assert side == 384
    for x, y in corners:
        assert 0 <= x <= 3840 - 384 and 432 <= y <= 2160 - 384  # below the top 2 of 10 stripes
    assert D.patch_positions("k", 100, 60, count=1, size=384, seed=0)[0] == 60


def test_augmentations_exclude_evaluation_perturbations() -> None:
    banned = {"brightness", "fog", "motion_blur", "shifted_pixels", "dead_rows", "pixel_trap"}
    assert not banned & set(D.AUGMENTATIONS)


def test_prepared_data_are_cached(datasets, tmp_path) -> None:
    train_dir, _ = datasets
    manifest = D.dataset_manifest(train_dir)
    params = tiny_config().prep_params()
    first = D.load_dataset(manifest, params, cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == len(manifest.samples)
    again = D.load_dataset(manifest, params, cache_dir=tmp_path)
    for a, b in zip(first, again, strict=True):
        assert a.key == b.key
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.region_labels, b.region_labels)
    assert first[0].image.shape == (36, 64, 3) and first[0].regions.shape == (2, 56, 56, 3)


def test_metrics_summary() -> None:
    truth = np.array([0, 0, 1, 1])
    pred = np.array([0, 1, 1, 1])
    s = summarise(confusion(truth, pred))
    assert s["per_class_iou"]["clutter"] == 0.5 and abs(s["per_class_iou"]["building"] - 2 / 3) < 1e-12
    assert s["per_class_iou"]["road"] is None  # absent from truth and prediction: undefined, not 0
    assert abs(s["miou"] - (0.5 + 2 / 3) / 2) < 1e-12
    figures = {"working_resolution": s, "hd_patches": s}
    assert compare_figures(figures, figures) == []
    other = summarise(confusion(truth, np.array([0, 0, 1, 1])))
    assert compare_figures(figures, {"working_resolution": other, "hd_patches": s})


# -- training ------------------------------------------------------------------------------------------
def test_a_few_steps_lower_the_loss(datasets) -> None:
    train_dir, _ = datasets
    config = tiny_config()
    samples = D.load_dataset(D.dataset_manifest(train_dir), config.prep_params())
    batches = sample_batch(samples, config, step=0)
    assert batches[0][0].shape == (2, 3, 32, 32) and batches[1] is not None
    torch.manual_seed(0)
    model = build_model(TINY_ARCH).train()
    model.set_dropout(0.0)
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    weights = torch.ones(NUM_CLASSES)
    losses = []
    for _ in range(15):
        loss = training_loss(model, batches, weights)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.7 * losses[0]


def test_batches_are_a_function_of_seed_and_step(datasets) -> None:
    train_dir, _ = datasets
    config = tiny_config()
    samples = D.load_dataset(D.dataset_manifest(train_dir), config.prep_params())
    a, b = sample_batch(samples, config, 3), sample_batch(samples, config, 3)
    assert torch.equal(a[0][0], b[0][0]) and torch.equal(a[1][1], b[1][1])
    assert not torch.equal(a[0][0], sample_batch(samples, config, 4)[0][0])


def test_train_config_round_trips_and_validates() -> None:
    config = tiny_config()
    assert TrainConfig.from_dict(config.to_dict()) == config
    assert config.region_size >= config.hd_crop_max
    with pytest.raises(ValueError, match="hd_crop_max"):
        tiny_config(hd_crop_min=64, hd_crop_max=32)
    with pytest.raises(ValueError, match="working_width"):
        tiny_config(working_width=128)


def test_steps_for_epochs() -> None:
    assert steps_for_epochs(200, 3, 4) == 150
    assert steps_for_epochs(5, 1, 4) == 2
    with pytest.raises(ValueError):
        steps_for_epochs(0, 1, 4)


def _stop_after(k: int):
    """A progress wrapper that interrupts the training loop after k steps (a crash)."""

    def wrapper(items, total=None, desc=""):
        if desc != "train":
            yield from items
            return
        for i, item in enumerate(items):
            if i == k:
                raise KeyboardInterrupt
            yield item

    return wrapper


def test_resume_continues_and_matches_an_uninterrupted_run(datasets, tmp_path) -> None:
    train_dir, val_dir = datasets
    config = tiny_config(baseline_pixels=0)
    full = tmp_path / "full" / "model.pt"
    card_full = train(train_dir, full, val_dir=val_dir, config=config)

    part = tmp_path / "part" / "model.pt"
    with pytest.raises(KeyboardInterrupt):
        train(train_dir, part, val_dir=val_dir, config=config, progress=_stop_after(4))
    assert load_checkpoint(checkpoint_path(part))["step"] in (3, 4)
    with pytest.raises(ValueError, match="checkpoint exists"):
        train(train_dir, part, val_dir=val_dir, config=config)
    with pytest.raises(ValueError, match="another configuration"):
        train(train_dir, part, val_dir=val_dir, config=tiny_config(baseline_pixels=0, lr=1e-3), options=RESUME)
    messages: list[str] = []
    card_part = train(train_dir, part, val_dir=val_dir, config=config, options=RESUME, log=messages.append)
    assert any(m.startswith("resuming from step") for m in messages)
    assert load_checkpoint(checkpoint_path(part))["step"] == config.steps

    full_state = load_checkpoint(checkpoint_path(full))["model"]
    part_state = load_checkpoint(checkpoint_path(part))["model"]
    for k, v in full_state.items():
        torch.testing.assert_close(part_state[k], v, atol=1e-5, rtol=1e-4)
    assert card_part["training"]["best_step"] == card_full["training"]["best_step"]
    assert card_full["training"]["steps"] == config.steps


def test_stop_at_cuts_a_run_short_on_the_same_schedule(datasets, tmp_path) -> None:
    train_dir, val_dir = datasets
    config = tiny_config(baseline_pixels=0, eval_every=2)
    full = tmp_path / "full" / "model.pt"
    train(train_dir, full, val_dir=val_dir, config=config)
    cut = tmp_path / "cut" / "model.pt"
    card = train(train_dir, cut, val_dir=val_dir, config=config, options=RunOptions(stop_at=4))
    assert card["training"]["stopped_at"] == 4 and card["training"]["history"][-1]["step"] == 4
    assert load_checkpoint(checkpoint_path(cut))["step"] == 4
    full_ckpt = load_checkpoint(checkpoint_path(full))  # the first 4 steps are those of the full run
    cut_losses = [h["loss"] for h in card["training"]["history"]]
    assert [h["loss"] for h in full_ckpt["history"][:2]] == pytest.approx(cut_losses)
    with pytest.raises(ValueError, match="stop_at"):
        train(train_dir, tmp_path / "bad" / "model.pt", val_dir=val_dir, config=config,
              options=RunOptions(stop_at=config.steps + 1))
    card = train(train_dir, cut, val_dir=val_dir, config=config, options=RESUME)  # and then to the end
    assert card["training"]["stopped_at"] is None and load_checkpoint(checkpoint_path(cut))["step"] == config.steps


def test_prefetched_batches_arrive_in_step_order_and_do_not_change_training(datasets, tmp_path) -> None:
    assert list(prefetched(lambda s: s * s, range(3, 40), workers=3, depth=6)) == [s * s for s in range(3, 40)]
    assert list(prefetched(lambda s: s + 1, range(5), workers=0, depth=0)) == [1, 2, 3, 4, 5]
    assert list(prefetched(lambda s: -s, range(9), workers=1, depth=2)) == [-s for s in range(9)]
    train_dir, val_dir = datasets
    config = tiny_config(baseline_pixels=0)
    plain = train(train_dir, tmp_path / "a" / "model.pt", val_dir=val_dir, config=config)
    ahead = train(train_dir, tmp_path / "b" / "model.pt", val_dir=val_dir, config=config,
                  options=RunOptions(prefetch=3))
    assert ahead["weights_sha256"] == plain["weights_sha256"]
    assert ahead["training"]["device"] == "cpu"


def test_a_missing_accelerator_is_a_clear_error(datasets, tmp_path, uav_el, capsys) -> None:
    with pytest.raises(ValueError, match="unknown device"):
        resolve_device("gpu-please")
    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA GPU")
    with pytest.raises(ValueError, match="no CUDA GPU"):
        resolve_device("cuda")
    train_dir, _ = datasets
    rc = uav_el(["train", "--data", str(train_dir), "--out", str(tmp_path / "m.pt"), "--device", "cuda"])
    assert rc == 2 and "--device" in capsys.readouterr().err and not (tmp_path / "m.pt").exists()


def test_lovasz_fine_tuning_is_recorded_and_old_checkpoints_still_resume(datasets, tmp_path) -> None:
    train_dir, val_dir = datasets
    config = tiny_config(baseline_pixels=0, loss="ce+lovasz")
    card = train(train_dir, tmp_path / "l" / "model.pt", val_dir=val_dir, config=config)
    assert "Lovász" in card["training"]["loss"] and card["training"]["config"]["loss"] == "ce+lovasz"
    with pytest.raises(ValueError, match="loss must be one of"):
        tiny_config(loss="dice")
    # a checkpoint written before the loss option existed resumes as the default "ce"
    part = tmp_path / "p" / "model.pt"
    with pytest.raises(KeyboardInterrupt):
        train(train_dir, part, config=tiny_config(baseline_pixels=0), progress=_stop_after(4))
    ckpt = checkpoint_path(part)
    state = load_checkpoint(ckpt)
    del state["config"]["loss"]
    torch.save(state, ckpt)
    done = train(train_dir, part, config=tiny_config(baseline_pixels=0), options=RESUME)
    assert done["training"]["config"]["loss"] == "ce"


def test_a_checkpoint_without_frame_options_resumes_and_the_card_records_them(datasets, tmp_path) -> None:
    train_dir, val_dir = datasets
    part = tmp_path / "model.pt"
    with pytest.raises(KeyboardInterrupt):
        train(train_dir, part, val_dir=val_dir, config=tiny_config(baseline_pixels=0), progress=_stop_after(4))
    ckpt = checkpoint_path(part)
    state = load_checkpoint(ckpt)
    del state["config"]["eval_protocol"]["frame_flip"]  # written before the options existed
    del state["config"]["eval_protocol"]["frame_scales"]
    torch.save(state, ckpt)
    done = train(train_dir, part, val_dir=val_dir, config=tiny_config(baseline_pixels=0), options=RESUME)
    assert done["evaluation"]["protocol"]["frame_flip"] is False
    assert done["evaluation"]["protocol"]["frame_scales"] == [1.0]
    flipped = tiny_config(baseline_pixels=0, eval_protocol=replace(tiny_config().eval_protocol, frame_flip=True))
    with pytest.raises(ValueError, match="frame_flip"):  # a changed protocol is not resumed silently
        train(train_dir, part, val_dir=val_dir, config=flipped, options=RESUME)
    scaled = tiny_config(baseline_pixels=0, eval_protocol=replace(tiny_config().eval_protocol, frame_scales=(1.5,)))
    with pytest.raises(ValueError, match="frame_scales"):
        train(train_dir, part, val_dir=val_dir, config=scaled, options=RESUME)


def test_resume_without_checkpoint_is_an_error(datasets, tmp_path) -> None:
    train_dir, _ = datasets
    with pytest.raises(ValueError, match="no checkpoint"):
        train(train_dir, tmp_path / "model.pt", config=tiny_config(), options=RESUME)


# -- the command line ----------------------------------------------------------------------------------
@pytest.fixture()
def uav_el(monkeypatch):
    monkeypatch.setattr(cli, "COMMANDS", {"train": "train", "model-card": "model_card"})
    return cli.main


def test_train_and_model_card_cli(datasets, tmp_path, uav_el, capsys) -> None:
    train_dir, val_dir = datasets
    out = tmp_path / "w" / "model.pt"
    rc = uav_el([
        "train", "--data", str(train_dir), "--val", str(val_dir), "--out", str(out), "--steps", "4",
        "--batch", "2", "--crop", "32", "--hd-crops", "0.03", "--hd-crop", "32-48", "--arch", "msdlite",
        "--widths", "8,8,16",
        "--working-width", "64", "--hd-eval-size", "48", "--cache-dir", str(tmp_path / "cache"),
        "--seed", "3",
    ])  # not --quiet: the summary lines are on stdout
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "validation mIoU" in captured.out and "baseline" in captured.out
    card = read_card(out)
    assert card["training"]["seed"] == 3 and card["training"]["steps"] == 4
    assert card["training"]["data"]["train"]["images"] == 4
    assert set(card["evaluation"]) >= {"working_resolution", "hd_patches", "protocol", "data"}
    assert len(card["evaluation"]["working_resolution"]["confusion"]) == NUM_CLASSES
    assert card["baseline"]["miou"] is not None and "miou_gap_to_cnn" in card["baseline"]
    audit = card["candidates"]  # the core model's candidates on the clean validation scenes
    assert audit["images"] == 2 and 0 <= audit["unsafe"] <= audit["candidates"]
    sep = audit["separation"]  # the LHD evidence's separation of unsafe from safe candidates
    assert sep["candidates"] == audit["candidates"] and sep["unsafe"] == audit["unsafe"]
    assert "candidates:" in captured.out

    assert uav_el(["model-card", "--weights", str(out)]) == 0
    assert "mIoU" in capsys.readouterr().out
    assert uav_el(["model-card", "--weights", str(out), "--verify", "--quiet", "--train", str(train_dir)]) == 0
    out_text = capsys.readouterr().out
    assert "model card verified" in out_text and "candidate audit" in out_text
    card["candidates"]["candidates"] += 1  # a recorded audit that the weights do not reproduce
    card_path(out).write_text(json.dumps(card))
    assert uav_el(["model-card", "--weights", str(out), "--verify", "--quiet"]) == 1
    assert "candidate audit: recorded" in capsys.readouterr().out
    card["candidates"]["candidates"] -= 1

    # A figure that does not match the weights: verification fails with exit code 1.
    card["evaluation"]["working_resolution"]["miou"] += 0.05
    card_path(out).write_text(json.dumps(card))
    assert uav_el(["model-card", "--weights", str(out), "--verify", "--quiet", "--data", str(val_dir)]) == 1
    assert "MISMATCH" in capsys.readouterr().out
    # Altered weights: a one-line error naming the file, exit code 2.
    out.write_bytes(out.read_bytes() + b"\0")
    assert uav_el(["model-card", "--weights", str(out), "--verify", "--quiet"]) == 2
    assert "SHA-256 mismatch" in capsys.readouterr().err


def test_train_cli_rejects_bad_options(datasets, tmp_path, uav_el, capsys) -> None:
    train_dir, _ = datasets
    rc = uav_el(["train", "--data", str(train_dir), "--out", str(tmp_path / "m.pt"), "--hd-crop", "64-32"])
    assert rc == 2 and "hd_crop_max" in capsys.readouterr().err
    rc = uav_el(["train", "--data", str(tmp_path / "missing"), "--out", str(tmp_path / "m.pt")])
    assert rc == 2 and "not found" in capsys.readouterr().err


def test_verify_reports_changed_validation_data(datasets, tmp_path) -> None:
    train_dir, val_dir = datasets
    out = tmp_path / "model.pt"
    train(train_dir, out, val_dir=val_dir, config=tiny_config(steps=2, baseline_pixels=0))
    other = fake_dataset(tmp_path / "other_val", 2, seed=9)
    result = verify_card(out, val_dir=other)
    assert not result.ok
    assert any("validation data hash differs" in p for p in result.problems)


def test_reissue_moves_the_card_to_another_copy_of_the_data(datasets, tmp_path, uav_el, capsys) -> None:
    train_dir, val_dir = datasets
    out = tmp_path / "model.pt"
    train(train_dir, out, val_dir=val_dir, config=tiny_config(steps=2))
    before = read_card(out)
    other_val = fake_dataset(tmp_path / "other_val", 2, seed=9)
    assert not verify_card(out, val_dir=other_val).ok

    assert uav_el(["model-card", "--weights", str(out), "--reissue", "--quiet"]) == 2
    assert "--reissue needs --data" in capsys.readouterr().err
    rc = uav_el(["model-card", "--weights", str(out), "--reissue", "--quiet", "--data", str(other_val),
                 "--train", str(train_dir)])
    assert rc == 0, capsys.readouterr().err
    assert "re-issued" in capsys.readouterr().out
    card = read_card(out)
    assert card["weights_sha256"] == before["weights_sha256"]
    assert card["training"] == before["training"]  # what it was trained on stays recorded
    assert card["evaluation"]["data"]["sha256"] == D.dataset_manifest(other_val).sha256
    assert card["evaluation"]["reissued"]["data"] == before["evaluation"]["data"]
    assert card["baseline"]["train_data"]["sha256"] == D.dataset_manifest(train_dir).sha256
    assert card["candidates"]["images"] == 2
    result = verify_card(out, val_dir=other_val, train_dir=train_dir)
    assert result.ok, result.problems
    assert uav_el(["model-card", "--weights", str(out), "--verify", "--quiet", "--data", str(other_val)]) == 0
    capsys.readouterr()
    # Without --data the audit uses the folder the card's figures come from, not the training machine's.
    assert uav_el(["model-card", "--weights", str(out), "--audit-candidates", "--quiet"]) == 0
    assert read_card(out)["candidates"]["data"] == str(other_val)

    # --frame-flip on: the protocol changes, figures follow, verify and the flight code follow the card
    assert uav_el(["model-card", "--weights", str(out), "--frame-flip", "on", "--quiet"]) == 2
    assert "--reissue" in capsys.readouterr().err
    assert uav_el(["model-card", "--weights", str(out), "--reissue", "--quiet", "--data", str(other_val),
                   "--frame-flip", "on", "--hd-patches", "3"]) == 0
    flipped = read_card(out)
    assert flipped["evaluation"]["protocol"]["frame_flip"] is True
    assert flipped["evaluation"]["protocol"]["hd_patches"] == 3 and flipped["evaluation"]["patches"] == 2 * 3
    assert flipped["evaluation"]["reissued"]["protocol"]["frame_flip"] is False
    assert Segmenter.load(out).frame_flip is True
    assert verify_card(out, val_dir=other_val).ok
    assert uav_el(["model-card", "--weights", str(out), "--quiet"]) == 0
    assert "mirror image" in capsys.readouterr().out

    # --frame-scales: the working frame fed to the network larger; recorded, followed, verified
    with pytest.raises(SystemExit) as bad:  # argparse: usage and the message on stderr
        uav_el(["model-card", "--weights", str(out), "--reissue", "--quiet", "--data", str(other_val),
                "--frame-scales", "5"])
    assert bad.value.code == 2
    assert "frame_scales must be" in capsys.readouterr().err
    assert uav_el(["model-card", "--weights", str(out), "--reissue", "--quiet", "--data", str(other_val),
                   "--frame-scales", "1,1.5", "--frame-flip", "off"]) == 0
    scaled = read_card(out)
    assert scaled["evaluation"]["protocol"]["frame_scales"] == [1.0, 1.5]
    assert scaled["evaluation"]["reissued"]["protocol"]["frame_scales"] == [1.0]
    assert scaled["evaluation"]["working_resolution"] != flipped["evaluation"]["working_resolution"]
    assert Segmenter.load(out).frame_scales == (1.0, 1.5)
    assert verify_card(out, val_dir=other_val).ok
    assert uav_el(["model-card", "--weights", str(out), "--quiet"]) == 0
    assert "fed to the network at x1, x1.5, softmax averaged" in capsys.readouterr().out


def test_warm_start_begins_from_the_parent_weights(datasets, tmp_path) -> None:
    train_dir, val_dir = datasets
    parent = tmp_path / "parent" / "model.pt"
    parent_card = train(train_dir, parent, val_dir=val_dir, config=tiny_config(baseline_pixels=0))
    sha = parent_card["weights_sha256"]

    # Zero steps' worth of learning rate: the child starts exactly where the parent ended.
    child = tmp_path / "child" / "model.pt"
    card = train(train_dir, child, config=tiny_config(baseline_pixels=0, steps=1, lr=1e-12, init_sha256=sha),
                 options=RunOptions(init_weights=parent))
    assert card["training"]["init"]["weights_sha256"] == sha
    assert card["training"]["total_steps"] == 1 + parent_card["training"]["steps"]
    parent_state = torch.load(parent, weights_only=True)
    child_state = torch.load(child, weights_only=True)
    for k, v in parent_state.items():
        if v.dtype.is_floating_point and "running" not in k:  # BatchNorm statistics move with any step
            torch.testing.assert_close(child_state[k], v, atol=1e-6, rtol=0)

    with pytest.raises(ValueError, match="not the configured init_sha256"):
        train(train_dir, tmp_path / "c2" / "m.pt", config=tiny_config(steps=1, init_sha256="0" * 64),
              options=RunOptions(init_weights=parent))
    other = ArchConfig(widths=(8, 8, 8), ms_channels=8, decoder_channels=8)
    with pytest.raises(ValueError, match="architecture"):
        train(train_dir, tmp_path / "c3" / "m.pt", config=tiny_config(steps=1, arch=other, init_sha256=sha),
              options=RunOptions(init_weights=parent))


def test_train_cli_warm_start_takes_the_parents_architecture(datasets, tmp_path, uav_el, capsys) -> None:
    train_dir, _ = datasets
    parent = tmp_path / "p" / "model.pt"
    train(train_dir, parent, config=tiny_config(baseline_pixels=0, steps=2))
    out = tmp_path / "c" / "model.pt"
    rc = uav_el(["train", "--data", str(train_dir), "--out", str(out), "--init", str(parent), "--steps", "1",
                 "--batch", "1", "--crop", "32", "--hd-crops", "0", "--working-width", "64", "--no-cache", "--quiet"])
    assert rc == 0, capsys.readouterr().err
    assert read_card(out)["architecture"] == read_card(parent)["architecture"]
    rc = uav_el(["train", "--data", str(train_dir), "--out", str(tmp_path / "d.pt"),
                 "--init", str(tmp_path / "nope.pt")])
    assert rc == 2 and "nope" in capsys.readouterr().err


def test_a_recomputed_candidate_audit_reproduces_the_counts_exactly_and_the_auroc_within_the_tolerance():
    """Another CPU's last bits may move the separation AUROC a little; the counts must be the card's."""
    from assurance.cli.model_card import audit_agreement

    def audit(auroc, candidates=1392):
        return {"images": 70, "candidates": candidates, "unsafe": 222, "images_without_candidate": 1,
                "separation": {"scores": {"max_forbidden_probability": {"auroc": auroc}}}}

    assert audit_agreement(audit(0.7073), audit(0.7073), 0.002) == (True, "candidate audit: 222 of 1392 unsafe, "
                                                                          "as recorded")
    ok, line = audit_agreement(audit(0.7073), audit(0.7083), 0.002)
    assert ok and "recorded 0.707300, recomputed 0.7083, within --tolerance 0.002" in line
    ok, line = audit_agreement(audit(0.7073), audit(0.7173), 0.002)
    assert not ok and "separation AUROC recorded 0.707300, recomputed 0.7173" in line
    ok, line = audit_agreement(audit(0.7073), audit(0.7073, candidates=1393), 0.002)
    assert not ok and "candidates=1392" in line and "candidates=1393" in line
