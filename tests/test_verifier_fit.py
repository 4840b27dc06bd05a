"""Fitting the candidate verifier: its training data, a few training steps, the record it writes, the command."""

from __future__ import annotations

import math

import numpy as np
import pytest

from el.base.decision import Disc

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")


def test_aux_target_and_mined_discs():
    from assurance.fitting.verifier_data import aux_target, jittered

    forbidden = np.zeros((100, 100), bool)
    forbidden[:, 50:] = True
    a = aux_target(forbidden, Disc(50.0, 50.0, 10.0), margin=0.5, grid=6)
    assert a.shape == (6, 6) and a[:, :3].max() == 0.0 and a[:, 3:].min() == 1.0
    edge = aux_target(forbidden, Disc(5.0, 50.0, 10.0), margin=0.5, grid=6)
    assert edge[:, 0].min() > 0.5  # outside the image counts as forbidden
    rng = np.random.default_rng(0)
    d = Disc(50.0, 50.0, 10.0)
    moved = jittered(d, rng, 6, 100, 100)
    dist = [math.hypot(m.x - d.x, m.y - d.y) / d.radius_px for m in moved]
    assert dist[0] <= 0.5 and 0.5 <= dist[1] <= 1.5 and all(0.0 <= m.x <= 100 and 0.0 <= m.y <= 100 for m in moved)


def test_lookalike_discs_lie_on_valid_ground_within_their_radius_of_forbidden_ground():
    """A look-alike disc is centred on ground the core model found valid, with a forbidden ground-truth pixel within
    its radius (on the working grid); none where nothing is valid or nothing is forbidden, and never more than asked."""
    from types import SimpleNamespace

    from conftest import TINY_H, TINY_W, TINY_WW

    from assurance.fitting.verifier_data import lookalike_discs
    from el.geometry.config import CoreConfig
    from el.landing.candidates import row_radii

    core = CoreConfig(working_width=TINY_WW)
    w, h = TINY_WW, TINY_WW * TINY_H // TINY_W
    radii = row_radii(core.geometry(w, h), core.safety, core.mode)
    forbidden = np.zeros((TINY_H, TINY_W), bool)
    forbidden[:, 200:204] = True  # a thin road on the right
    valid = np.zeros((h, w), bool)
    valid[:, 60:] = np.isfinite(radii)[:, None]
    result = SimpleNamespace(working_size=(w, h), input_size=(TINY_W, TINY_H), valid=valid, radii=radii)
    discs = lookalike_discs(result, forbidden, np.random.default_rng(0), 12)
    assert len(discs) == 12 and len({(d.x, d.y) for d in discs}) == 12
    road_x = 202.0
    for d in discs:
        assert d.x >= 60 * TINY_W / w and abs(d.x - road_x) < d.radius_px + 2 * TINY_W / w
    assert lookalike_discs(result, np.zeros_like(forbidden), np.random.default_rng(0), 12) == []
    nothing_valid = SimpleNamespace(working_size=(w, h), input_size=(TINY_W, TINY_H), valid=np.zeros_like(valid),
                                    radii=radii)
    assert lookalike_discs(nothing_valid, forbidden, np.random.default_rng(0), 3) == []
    few = lookalike_discs(result, forbidden, np.random.default_rng(0), 10**6)
    assert 12 < len(few) < int(valid.sum())  # every near cell once, the far ones never
    from assurance.fitting.verifier_data import CropSettings, scene_crops
    from el.classes.labels import UAVID

    with pytest.raises(ValueError, match="look-alike"):  # given candidates carry no valid ground to draw from
        scene_crops(np.zeros((TINY_H, TINY_W, 3), np.uint8), np.zeros((TINY_H, TINY_W), np.int64), None,
                    labels=UAVID, settings=CropSettings(core=core, size=32, lookalikes=1),
                    rng=np.random.default_rng(0), scene=0, candidates=[])


def _crops(n: int, rng: np.random.Generator):
    from assurance.fitting.verifier_data import CropSet

    unsafe = np.arange(n) % 3 == 0
    crops = rng.integers(60, 120, (n, 32, 32, 3), dtype=np.uint8)
    crops[unsafe, :, 14:18] = 250  # a bright stripe through the disc: "forbidden"
    aux = np.zeros((n, 8, 8), np.float32)
    aux[unsafe, :, 3:5] = 1.0
    return CropSet(crops, unsafe, aux, np.arange(n) // 4, np.ones(n, bool), np.zeros(n, np.int64),
                   np.zeros((n, 3)))


def test_a_few_steps_select_on_held_out_and_write_a_record_that_flies(tmp_path):
    from assurance.fitting import verifier_fit as vf
    from assurance.fitting.verifier_fit import check_export, choose_fusion, export_onnx, verifier_body, write_verifier
    from assurance.fitting.verifier_train import TrainConfig, predict, train_verifier
    from el.base.hashing import sha256_bytes
    from el.classes.labels import UAVID
    from el.monitors.verifier import VerifierMonitor

    rng = np.random.default_rng(0)
    train, held = _crops(48, rng), _crops(24, rng)
    cfg = TrainConfig(size=32, steps=4, batch=8, eval_every=2, threads=1)
    result = train_verifier(train, held, cfg, pretrained=False, log=lambda s: None)
    assert result.best_step in (2, 4) and len(result.curve) == 2 and result.steps_run == 4
    onnx = export_onnx(result.model)
    assert check_export(onnx, result.model, held.crops[:4]) < 1e-3
    p = predict(result.model, held.crops)
    fusion = choose_fusion(held.unsafe, p, np.where(held.unsafe, 0.7, 0.3), learned_sha256="f" * 64, recall=0.95)
    assert 0.0 <= fusion["weight"] <= 1.0 and fusion["held_out"]["recall"] >= 0.95
    body = verifier_body(result, cfg, train, held, export=vf.OnnxExport("v.onnx", sha256_bytes(onnx), 0.0),
                         choice=vf.HeldOutChoice(p=p, recall=0.95, fusion=fusion),
                         sources=vf.VerifierSources(splits={"train": "t", "train_sha256": "1" * 64},
                                                    weights={"sha256": "abc"}, command="uav-el fit-verifier ...",
                                                    labels="uavid", imagenet={}))
    assert body["held_out"]["recall"] >= 0.95 and body["training"]["sha256"] == "1" * 64
    write_verifier(tmp_path / "v.json", body, onnx)
    m = VerifierMonitor(labels=UAVID, model=str(tmp_path / "v.json"))
    assert m.threshold == pytest.approx(body["threshold"])
    img = np.random.default_rng(1).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    v = m.check_many(img, [Disc(32.0, 32.0, 8.0)], None, seeds=[0])
    assert 0.0 <= v[0].score <= 1.0


def test_the_blocks_to_1_16_learn_when_only_the_low_part_is_frozen():
    from assurance.fitting.verifier_train import TrainConfig, train_verifier

    rng = np.random.default_rng(2)
    train, held = _crops(32, rng), _crops(16, rng)
    cfg = TrainConfig(size=32, steps=2, batch=8, eval_every=2, threads=1, views=2, frozen="low")
    result = train_verifier(train, held, cfg, pretrained=False, log=lambda s: None)
    assert result.steps_run == 2 and len(result.curve) == 1
    with pytest.raises(ValueError, match="frozen"):
        TrainConfig(frozen="none")


def test_the_anchor_keeps_the_learning_blocks_features_near_their_starting_ones():
    """``anchor``: the learning blocks' features start at their ImageNet ones (gap nought: batch norms in eval mode)
    and a strong pull keeps them nearer than none does, at a learning rate that moves them; the gap is logged;
    the whole encoder frozen, there is nothing to anchor, and it is refused."""
    import torch

    from assurance.fitting.verifier_net import VerifierNet
    from assurance.fitting.verifier_train import (
        TrainConfig,
        _anchored_forward,
        as_input,
        frozen_session,
        low_features,
        train_verifier,
    )

    rng = np.random.default_rng(4)
    train, held = _crops(32, rng), _crops(16, rng)
    start = VerifierNet(size=32, margin=1.0, deep=True)
    start.load_imagenet()
    start.eval()
    x = as_input(train.crops[:16])
    gaps = {}
    for anchor in (0.0, 100.0):
        cfg = TrainConfig(size=32, steps=6, batch=8, eval_every=6, threads=1, frozen="low", lr=0.01,
                          encoder_lr_scale=1.0, anchor=anchor)
        result = train_verifier(train, held, cfg, log=lambda s: None)
        assert [c["step"] for c in result.curve] == [6] and ("anchor_gap" in result.curve[0]) == bool(anchor)
        final = result.model  # the last step's: the only one evaluated
        with torch.no_grad():
            ref = start.mid(start.low(x))[0]
            got = final.eval().mid(final.low(x))[0]
        gaps[anchor] = float((got - ref).pow(2).mean() / ref.var())
    assert gaps[100.0] < 0.8 * gaps[0.0]
    f8, *targets = low_features(frozen_session(start, encoder=True, threads=1), x.numpy())
    assert not start.training  # the export left it as it found it
    scales = [float(t.float().var()) for t in targets]
    assert float(_anchored_forward(start, f8, targets, scales)[2]) < 1e-4  # the pull starts at nought
    for kw in ({"anchor": 1.0}, {"anchor": -1.0, "frozen": "low"}, {"anchor": float("nan"), "frozen": "low"}):
        with pytest.raises(ValueError, match="anchor"):
            TrainConfig(**kw)


def test_spilled_training_crops_are_the_crops_held_in_memory(tiny_campaign, tmp_path):
    """``collect_crops(spill=FILE)``: the crops written to disk scene by scene and mapped back read-only are the
    ones kept in memory, and so are the truth, scenes and discs joined beside them."""
    from conftest import TINY_WW
    from helpers import OracleSegmenter

    from assurance.fitting.verifier_data import CropSettings, collect_crops
    from el.geometry.config import CoreConfig

    settings = CropSettings(core=CoreConfig(n_star=6, working_width=TINY_WW), size=32, jitter=1)
    kept = collect_crops(tiny_campaign["data"], OracleSegmenter(TINY_WW), settings=settings)
    spilled = collect_crops(tiny_campaign["data"], OracleSegmenter(TINY_WW), settings=settings,
                            spill=tmp_path / "crops.u8")
    assert len(kept.unsafe) > 10 and kept.is_candidate.any() and (~kept.is_candidate).any()
    assert isinstance(spilled.crops, np.memmap) and not spilled.crops.flags.writeable
    assert (tmp_path / "crops.u8").stat().st_size == kept.crops.nbytes
    for name in kept.__dataclass_fields__:
        assert np.array_equal(getattr(kept, name), getattr(spilled, name)), name
    assert set(kept.scene) == set(range(10))


def test_fit_verifier_command_is_listed_and_checks_its_options(tmp_path, capsys):
    from assurance.cli import COMMANDS, main

    assert COMMANDS["fit-verifier"] == "fit_verifier"
    assert main(["fit-verifier", "--data", str(tmp_path / "nope"), "--val", str(tmp_path),
                 "--out", str(tmp_path / "v.json")]) == 2
    assert "no such folder" in capsys.readouterr().err
    for option, value, says in (("--fuse-layers", "7", "fuse_layers"), ("--jitter", "-1", "jitter"),
                                ("--lookalikes", "-2", "lookalikes"),
                                ("--images", "0", "images"), ("--margin", "5", "margin")):
        assert main(["fit-verifier", "--data", str(tmp_path), "--val", str(tmp_path), "--out", str(tmp_path / "v.json"),
                     option, value]) == 2, option
        assert says in capsys.readouterr().err, option


@pytest.mark.parametrize("kw, match", [({"margin": -1.0}, "margin"), ({"margin": 50.0}, "margin"),
                                       ({"lr": float("nan")}, "lr"), ({"lr": 0.0}, "lr"), ({"minutes": 0.0}, "minutes"),
                                       ({"size": 7}, "multiple of 32"), ({"steps": 0}, "steps"),
                                       ({"augment": "fog"}, "augment"), ({"augment": "optics"}, "views >= 2"),
                                       ({"rank_weight": -1.0}, "rank_weight"),
                                       ({"rank_weight": float("nan")}, "rank_weight")])
def test_training_settings_out_of_range_are_refused(kw, match):
    """A negative or huge margin (a crop window that grows as its square), a learning rate that is not a positive
    number, a zero time limit, an augmentation set that is not one or that has no augmented view to change: refused
    before any crop is cut."""
    from assurance.fitting.verifier_train import TrainConfig

    with pytest.raises(ValueError, match=match):
        TrainConfig(**kw)


@pytest.mark.parametrize("kw, match", [({"jitter": -1}, "jitter"), ({"images": 0}, "images"),
                                       ({"lookalikes": -1}, "lookalikes"),
                                       ({"recall": 1.0}, "recall")])
def test_fit_options_out_of_range_are_refused(kw, match):
    from assurance.fitting.verifier_fit import VerifierFitOptions

    with pytest.raises(ValueError, match=match):
        VerifierFitOptions(**kw)


def test_the_optics_augmentation_changes_the_pixels_not_the_targets_and_repeats_with_its_seed():
    """``augment="optics"`` (lens, codec, exposure) gives crops in [0, 1] that differ from the colour set's drawn
    from the same seed, and the same crops again from the same seed; most draws change a crop."""
    from assurance.fitting.verifier_train import augment, optics

    data = _crops(8, np.random.default_rng(5))
    crops, aux = data.crops, data.aux
    x_c, a_c = augment(crops, aux, 32, np.random.default_rng(1))
    x_o, a_o = augment(crops, aux, 32, np.random.default_rng(1), kind="optics")
    again, _ = augment(crops, aux, 32, np.random.default_rng(1), kind="optics")
    assert x_o.shape == x_c.shape == (8, 3, 32, 32) and 0.0 <= x_o.min() and x_o.max() <= 1.0
    assert np.array_equal(x_o, again) and not np.allclose(x_o, x_c)
    assert a_o.shape == a_c.shape
    img = crops[0]
    changed = [not np.array_equal(optics(img, np.random.default_rng(s)), img) for s in range(8)]
    assert sum(changed) >= 6  # each of four steps with probability 1/2: all skipped 1 time in 16


def test_ranking_pairs_are_an_unsafe_and_a_safe_crop_of_one_scene_and_train():
    """The ranking loss's pairs: an unsafe crop and a safe one of the same scene, every such pair reachable, none
    from a scene without both; a few steps with the loss train and select as without it."""
    from assurance.fitting.verifier_train import ScenePairs, TrainConfig, train_verifier

    scene = np.array([0, 0, 0, 1, 1, 2, 2, 2])
    unsafe = np.array([1, 0, 0, 1, 1, 0, 1, 0], bool)
    pairs = ScenePairs(scene, unsafe)
    drawn = {tuple(map(int, p)) for p in pairs.draw(np.random.default_rng(0), 400)}
    assert len(pairs) == 2 and drawn == {(0, 1), (0, 2), (6, 5), (6, 7)}  # scene 1 has no safe crop
    assert len(ScenePairs(np.zeros(3, int), np.zeros(3, bool))) == 0
    assert len(ScenePairs(np.zeros(3, int), np.ones(3, bool))) == 0
    rng = np.random.default_rng(0)
    train, held = _crops(48, rng), _crops(24, rng)
    cfg = TrainConfig(size=32, steps=4, batch=8, eval_every=2, threads=1, rank_weight=1.0)
    result = train_verifier(train, held, cfg, pretrained=False, log=lambda s: None)
    assert result.steps_run == 4 and result.best_step in (2, 4) and math.isfinite(result.curve[-1]["loss"])


def test_the_command_line_defaults_are_the_training_configurations():
    """`uav-el fit-verifier` without options trains as TrainConfig() says (256 px, one view, the encoder frozen)."""
    import argparse
    from dataclasses import fields

    from assurance.cli.fit_verifier import add_arguments
    from assurance.fitting.verifier_train import AUGMENTS, FROZEN, TrainConfig

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    cfg = TrainConfig()
    for f in fields(TrainConfig):
        default = parser.get_default(f.name)
        if default is not None:
            assert default == getattr(cfg, f.name), f.name
    assert (cfg.size, cfg.views) == (256, 1)
    choices = {a.dest: tuple(a.choices) for a in parser._actions if a.choices}
    assert choices["frozen"] == FROZEN and choices["augment"] == AUGMENTS  # the command offers what training takes


def test_a_deep_verifier_reads_the_1_32_features_trains_on_them_and_exports():
    """``deep``: the frozen pass yields three levels, the head reads all of them, and the export flies as trained."""
    from assurance.fitting.verifier_fit import check_export, export_onnx
    from assurance.fitting.verifier_net import VerifierNet
    from assurance.fitting.verifier_train import TrainConfig, frozen_session, low_features, train_verifier

    rng = np.random.default_rng(3)
    train, held = _crops(32, rng), _crops(16, rng)
    net = VerifierNet(size=32, margin=0.5, width=8, deep=True).eval()
    x = train.crops[:3].transpose(0, 3, 1, 2).astype(np.float32) / 255.0
    levels = low_features(frozen_session(net, encoder=True, threads=1), x)
    assert [tuple(f.shape[1:]) for f in levels] == [(40, 4, 4), (112, 2, 2), (320, 1, 1)]
    with pytest.raises(ValueError, match="multiple of 32"):
        TrainConfig(size=48, deep=True)
    cfg = TrainConfig(size=32, steps=2, batch=8, eval_every=2, threads=1, deep=True)
    result = train_verifier(train, held, cfg, pretrained=False, log=lambda s: None)
    assert result.model.depth == 16 and result.model.lat32 is not None
    assert check_export(export_onnx(result.model), result.model, held.crops[:4]) < 1e-3


def test_features_spilled_to_files_are_the_features_kept_in_memory(tmp_path):
    """``spill``: the training crops' features go to memory-mapped files in the folder given, the same numbers as in
    memory (a split too large for the machine's memory trains from the page cache)."""
    from assurance.fitting.verifier_net import VerifierNet
    from assurance.fitting.verifier_train import TrainConfig, cached_views, frozen_session

    rng = np.random.default_rng(5)
    train = _crops(20, rng)
    cfg = TrainConfig(size=32, deep=True, frozen="encoder")
    session = frozen_session(VerifierNet(size=32, margin=0.5, width=8, deep=True).eval(), encoder=True, threads=1)
    kept, aux, y = cached_views(session, train, cfg, np.random.default_rng(0), lambda s: None)
    spilled, aux2, y2 = cached_views(session, train, cfg, np.random.default_rng(0), lambda s: None, spill=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["features-0.f16", "features-1.f16", "features-2.f16"]
    assert len(kept) == 3 and all(torch.equal(a, b) for a, b in zip(kept, spilled, strict=True))
    assert torch.equal(aux, aux2) and np.array_equal(y, y2)
    assert (tmp_path / "features-0.f16").stat().st_size == kept[0].numel() * 2


def test_more_fuse_layers_widen_what_each_cell_of_the_map_sees_and_export():
    """``fuse_layers``: that many 3x3 convolutions over the fused 1/8 map; a cell's logit then depends on cells two
    away (with one layer it cannot), and the exported network flies as trained."""
    import torch

    from assurance.fitting.verifier_fit import check_export, export_onnx
    from assurance.fitting.verifier_net import VerifierNet
    from assurance.fitting.verifier_train import TrainConfig, train_verifier

    rng = np.random.default_rng(4)
    train, held = _crops(32, rng), _crops(16, rng)
    cfg = TrainConfig(size=32, steps=2, batch=8, eval_every=2, threads=1, deep=True, fuse_layers=3)
    model = train_verifier(train, held, cfg, pretrained=False, log=lambda s: None).model
    assert sum(isinstance(m, torch.nn.Conv2d) and m.kernel_size == (3, 3) for m in model.fuse) == 3
    f8 = torch.zeros(1, 40, 4, 4)
    probe = f8.clone()
    probe[0, :, 0, 0] = 5.0  # a change two cells from (2, 2)
    lat = [torch.zeros(1, 112, 2, 2), torch.zeros(1, 320, 1, 1)]

    def cell(net: VerifierNet, x: torch.Tensor) -> float:
        with torch.no_grad():
            return net.head(x, *lat)[1][0, 0, 2, 2].item()

    assert cell(model, f8) != cell(model, probe)
    one = VerifierNet(size=32, margin=0.5, deep=True).eval()  # one layer: (2, 2) sees only (1..3, 1..3)
    assert cell(one, f8) == cell(one, probe)
    assert check_export(export_onnx(model), model, held.crops[:4]) < 1e-3
    for bad in (0, 7, 2.5, True):
        with pytest.raises(ValueError, match="fuse_layers"):
            TrainConfig(fuse_layers=bad)


def test_one_fuse_layer_is_the_network_the_shipped_verifier_was_trained_as():
    """The default keeps the fused map's single 3x3 layer under the same state-dict names, so a network trained
    before ``fuse_layers`` existed loads unchanged."""
    from assurance.fitting.verifier_net import VerifierNet

    keys = [k for k in VerifierNet(size=32).state_dict() if k.startswith("fuse")]
    assert keys == ["fuse.0.weight", "fuse.1.weight", "fuse.1.bias", "fuse.1.running_mean", "fuse.1.running_var",
                    "fuse.1.num_batches_tracked"]
