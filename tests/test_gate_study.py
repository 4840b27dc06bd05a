"""The frame-gate study's frames (``assurance.fitting.gate_frames``): the out-of-domain sets it makes and
its tap cache, saved set by set so that a rerun taps only the sets it lacks."""

from __future__ import annotations

import sys

import numpy as np
from helpers import TINY_ARCH, write_textured_scenes

from assurance.fitting import gate_frames as gf

SIZE = (128, 72)


def test_the_other_world_and_the_night_are_frames_of_the_size_asked(tmp_path):
    world = gf.other_world(n=2, size=SIZE)
    assert [w.shape for w in world] == [(72, 128, 3)] * 2 and all(w.dtype == np.uint8 for w in world)
    assert not np.array_equal(world[0], world[1]) and np.array_equal(world[0], gf.other_world(n=1, size=SIZE)[0])
    scenes = write_textured_scenes(tmp_path / "val", range(2), *SIZE)
    dark = gf.night(gf.scene_images(scenes))
    day = gf.read_image(gf.scene_images(scenes)[0])
    assert dark[0].shape == day.shape and np.median(dark[0]) < 0.25 * np.median(day)


def test_the_tap_cache_is_saved_per_set_and_a_rerun_taps_only_what_it_lacks(tmp_path, monkeypatch, one_torch_thread):
    import types

    import torch

    from el.classes.labels import UAVID
    from el.segmentation.architectures import build_model
    from el.segmentation.inference import Segmenter

    root = tmp_path / "data"
    write_textured_scenes(root / "train", range(2), *SIZE)
    write_textured_scenes(root / "val", range(100, 103), *SIZE)
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH), working_width=64, labels=UAVID)
    # the photographs come from scikit-image (the "gates" extra), which the test environment need not have
    skimage = types.ModuleType("skimage")
    skimage.data = types.ModuleType("skimage.data")
    monkeypatch.setitem(sys.modules, "skimage", skimage)
    monkeypatch.setitem(sys.modules, "skimage.data", skimage.data)
    monkeypatch.setattr(gf, "photos", lambda size: [np.full((size[1], size[0], 3), 90, np.uint8)] * 10)
    out = tmp_path / "taps.npz"
    gf.collect(root, seg, out, size=SIZE)
    cache = gf.load(out)
    sets = dict.fromkeys(str(s) for s in cache["set"])
    assert list(sets)[:3] == ["train", "val_sev3", "val_sev45"]
    assert {"ood_world", "ood_night", "ood_photos", "ood_noise", "ood_constant"} <= set(sets)
    assert (cache["set"] == "train").sum() == 2 * 11 and cache["pooled"].shape[0] == len(cache["set"])

    calls = []
    monkeypatch.setattr(seg, "predict_frame", lambda rgb: calls.append(rgb.shape))
    gf.collect(root, seg, out, size=SIZE)  # complete: nothing is tapped again
    assert calls == [] and len(gf.load(out)["set"]) == len(cache["set"])
    monkeypatch.delattr(seg, "predict_frame")
    keep = cache["set"] != "ood_world"  # a run cut short before the last sets: only those are tapped
    np.savez_compressed(out, **{k: v[keep] for k, v in cache.items()})
    gf.collect(root, seg, out, size=SIZE)
    again = gf.load(out)
    assert (again["set"] == "ood_world").sum() == 10 and len(again["set"]) == len(cache["set"])
