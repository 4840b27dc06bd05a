"""Worked example 2: a foreign palette. Synthetic scenes re-coloured to another label set (same eight classes,
other names, other colours, another id order), declared in a YAML label file and evaluated with the network
wrapped in a class map onto that set, give the same campaign readouts as the originals."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import TINY_ARCH, OracleSegmenter, scene_ids

from assurance.campaign import readouts
from assurance.campaign.run import CampaignConfig, Execution, run_campaign
from assurance.dataio.uavid import iter_samples, read_labels, write_sample
from assurance.fitting.network.weights_io import save_weights
from assurance.scenes.recolour import class_lut, recolour_dataset
from el.base.errors import DataError, LabelColourError
from el.classes.labels import UAVID, ids_to_colors, load_label_set
from el.geometry.config import CoreConfig
from el.segmentation.architectures import build_model
from el.segmentation.class_map import MappedModel
from el.segmentation.factory import load_model

W, H = 512, 288
MONITORS = ("lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.9", "msp", "entropy", "energy")
TIMING = {"read_s", "perturb_s", "segmentation_s", "candidates_s", "monitoring_s", "total_s", "overhead_s",
          "seconds"}

# The foreign set as a user declares it: the UAVid classes renamed, recoloured and in another id order
# (the hazard score and the forbidden flag follow the class, as they must for the readouts to agree).
FOREIGN_YAML = """\
name: city_survey
classes:
  - {id: 0, name: asphalt, rgb: [90, 90, 90], forbidden: true}           # UAVid road
  - {id: 1, name: lawn, rgb: [20, 200, 20], forbidden: false, hazard_score: 0.0}   # low_vegetation
  - {id: 2, name: house, rgb: [200, 30, 30], forbidden: true}            # building
  - {id: 3, name: driving_vehicle, rgb: [30, 30, 200], forbidden: true}  # moving_car
  - {id: 4, name: pedestrian, rgb: [250, 200, 0], forbidden: false, hazard_score: 1.0}  # human
  - {id: 5, name: canopy, rgb: [0, 90, 40], forbidden: false, hazard_score: 3.0}    # tree
  - {id: 6, name: parked_vehicle, rgb: [0, 200, 200], forbidden: true}   # static_car
  - {id: 7, name: misc, rgb: [255, 255, 255], forbidden: false, hazard_score: 2.0}  # clutter
"""
TO_FOREIGN = {"road": "asphalt", "low_vegetation": "lawn", "building": "house", "moving_car": "driving_vehicle",
              "human": "pedestrian", "tree": "canopy", "static_car": "parked_vehicle", "clutter": "misc"}


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    path = tmp_path_factory.mktemp("labels") / "city_survey.yaml"
    path.write_text(FOREIGN_YAML, encoding="utf-8")
    return load_label_set(path)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory, foreign):
    """Three scenes in UAVid colours, and the same scenes re-coloured to the foreign palette."""
    root = tmp_path_factory.mktemp("scenes")
    rng = np.random.default_rng(0)
    for i in range(3):
        ids = scene_ids(W, H, seed=i, road_col=60 + 90 * i)
        ids[200:204, 300:304] = 6  # a person
        ids[220:226, 100:110] = 3  # a parked car
        img = ids_to_colors(ids).astype(np.int16) + rng.integers(-20, 20, (H, W, 3))
        write_sample(root / "uavid", "seq00", f"{i:06d}", np.clip(img, 0, 255).astype(np.uint8), ids, labels=UAVID)
    meta = root / "uavid" / "seq00" / "meta"
    meta.mkdir()
    (meta / "000000.json").write_text('{"note": "copied unchanged"}', encoding="utf-8")
    summary = recolour_dataset(root / "uavid", root / "foreign", UAVID, foreign, TO_FOREIGN)
    assert summary["labels"] == 3 and set(summary["pixels"]) <= set(foreign.names)
    return root / "uavid", root / "foreign"


@pytest.fixture(scope="module")
def rendered(tmp_path_factory, foreign):
    """Two scenes rendered by the synthetic city (with their meta: the world model the clearance reads), re-coloured."""
    from assurance.scenes.generate import write_dataset

    root = tmp_path_factory.mktemp("rendered")
    write_dataset(root / "uavid", 2, seed=0, split="val", size=(320, 180), progress=False)
    recolour_dataset(root / "uavid", root / "foreign", UAVID, foreign, TO_FOREIGN)
    return root / "uavid", root / "foreign"


def _tables(run):
    out = {}
    for name in ("images", "candidates"):
        df = readouts.load_table(run, name)
        df = df[[c for c in df.columns if c not in TIMING]]
        out[name] = df.sort_values([c for c in ("key", "perturbation", "monitor", "rank") if c in df]).reset_index(
            drop=True)
    return out


def _in_uavid_names(tables):
    """Monitor reasons name the classes in the set's own words: say them in UAVid's to compare."""
    back = {v: k for k, v in TO_FOREIGN.items()}
    pattern = "|".join(sorted(back, key=len, reverse=True))
    for df in tables.values():
        if "reason" in df:
            df["reason"] = df["reason"].str.replace(pattern, lambda m: back[m.group(0)], regex=True)
    return tables


def _assert_same_readouts(a, b, *, float_rtol: float = 0.0):
    """Equal tables; with ``float_rtol`` the float columns may differ by that much (everything else exactly)."""
    differ = []
    for name in ("images", "candidates"):
        assert len(a[name]) > 0
        np.testing.assert_array_equal(a[name].columns, b[name].columns)
        for col in a[name].columns:
            x, y = a[name][col].to_numpy(), b[name][col].to_numpy()
            if float_rtol and x.dtype.kind == "f" and not np.array_equal(x, y, equal_nan=True):
                differ.append(f"{name}.{col}")
                np.testing.assert_allclose(x, y, rtol=float_rtol, atol=float_rtol, err_msg=f"{name}.{col}")
            else:
                np.testing.assert_array_equal(x, y, err_msg=f"{name}.{col}")
    return differ


def test_recolouring_keeps_images_and_meta_and_maps_every_class(scenes, foreign):
    src, dst = scenes
    for s, t in zip(iter_samples(src), iter_samples(dst), strict=True):
        assert s.image_path.read_bytes() == t.image_path.read_bytes()
        ids = read_labels(s.label_path, labels=UAVID)
        back = read_labels(t.label_path, foreign)
        for name, to in TO_FOREIGN.items():
            np.testing.assert_array_equal(back == foreign.ids[to], ids == UAVID.ids[name])
        with pytest.raises(LabelColourError):
            read_labels(t.label_path, labels=UAVID)  # no longer UAVid colours
    assert (dst / "seq00" / "meta" / "000000.json").read_text() == '{"note": "copied unchanged"}'


def test_campaign_readouts_equal_the_originals_with_the_oracle(tmp_path, scenes, foreign):
    src, dst = scenes
    oracle = OracleSegmenter(256)
    cfg = CampaignConfig(perturbations=("none", "fog"), monitors=MONITORS, core=CoreConfig(n_star=6, working_width=256))
    run_campaign(src, tmp_path / "a", cfg, segmenter=oracle, execution=Execution(progress=False))
    mapped = MappedModel(oracle, TO_FOREIGN, foreign)
    run_campaign(dst, tmp_path / "b", cfg, segmenter=mapped, execution=Execution(progress=False))
    a, b = _tables(tmp_path / "a"), _in_uavid_names(_tables(tmp_path / "b"))
    assert (a["images"]["fault"] == "").all()
    assert a["candidates"]["true_unsafe"].any() and not a["candidates"]["true_unsafe"].all()
    _assert_same_readouts(a, b)


def test_campaign_readouts_equal_the_originals_with_the_network(tmp_path, rendered, foreign):
    """The built-in network (tiny, random weights) on rendered scenes: frame, patch, shared trunk and MC dropout
    through the map, and the clearance from the scenes' copied meta."""
    src, dst = rendered
    torch.manual_seed(0)
    model = build_model(TINY_ARCH)
    with torch.no_grad():
        model.classifier.weight *= 100.0  # sharper logits: a varied map (some forbidden pixels) from random weights
    path = tmp_path / "tiny.pt"
    save_weights(model, path)
    seg = load_model(str(path), threads=1, working_width=160)
    cfg = CampaignConfig(perturbations=("none",), monitors=MONITORS, core=CoreConfig(n_star=4, working_width=160))
    run_campaign(src, tmp_path / "a", cfg, segmenter=seg, execution=Execution(progress=False))
    run_campaign(dst, tmp_path / "b", cfg, segmenter=MappedModel(seg, TO_FOREIGN, foreign),
                 execution=Execution(progress=False))
    a, b = _tables(tmp_path / "a"), _in_uavid_names(_tables(tmp_path / "b"))
    assert (a["images"]["fault"] == "").all() and len(a["candidates"]) > 0
    assert np.isfinite(a["candidates"]["clearance_m"]).any()
    # Bit for bit but sums over classes, which another id order rounds differently: the semantic hazard
    # (el.landing.ranking.semantic_hazard sums the weighted class planes in id order, float32; measured up to 3.7e-9)
    # and the entropy score (measured 2.2e-16). Decisions, ranks, positions, truth, clearance, acceptances and
    # every other monitor score are identical.
    differ = _assert_same_readouts(a, b, float_rtol=1e-6)
    assert set(differ) <= {"candidates.hazard", "candidates.hazard_semantic", "candidates.score"}
    ca, cb = a["candidates"], b["candidates"]
    assert set(ca["monitor"][ca["score"].to_numpy() != cb["score"].to_numpy()]) <= {"entropy", "energy"}


def test_recolouring_refuses_what_would_change_the_truth(tmp_path, scenes, foreign):
    src, _ = scenes
    with pytest.raises(ValueError, match="'road' -> safe class 'lawn'"):
        class_lut(UAVID, foreign, {**TO_FOREIGN, "road": "lawn"})
    with pytest.raises(ValueError, match="source class 'human' is not mapped"):
        class_lut(UAVID, foreign, {k: v for k, v in TO_FOREIGN.items() if k != "human"})
    with pytest.raises(ValueError, match="'tree' -> 'oak'"):
        class_lut(UAVID, foreign, {**TO_FOREIGN, "tree": "oak"})
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "x").write_text("")
    with pytest.raises(DataError, match="not an empty folder"):
        recolour_dataset(src, tmp_path / "out", UAVID, foreign, TO_FOREIGN)


def test_recolour_names_the_scene_meta_class_shares_in_the_target_classes(rendered, foreign):
    """The report's class balance reads the scene meta: after recolour it named UAVid's classes for another set."""
    import json

    src, dst = rendered
    labels = foreign
    for before in sorted(src.rglob("meta/*.json")):
        old = json.loads(before.read_text())["class_shares"]
        new = json.loads((dst / before.relative_to(src)).read_text())["class_shares"]
        assert set(new) <= set(labels.names) and set(new) != set(old)
        assert abs(sum(new.values()) - sum(v for k, v in old.items() if TO_FOREIGN.get(k) in labels.names)) < 1e-9
