"""Label sets (el.classes.labels.LabelSet): the UAVid default, a user's own set, and the flight code driven by one."""

from __future__ import annotations

import copy
import json
import pickle

import numpy as np
import pytest
import torch
from torch import nn

import el.classes.labels as lab
from assurance.campaign.gt_pipeline import decide_from_labels
from assurance.campaign.truth import disc_pixels, true_hazard
from assurance.dataio.uavid import read_labels, write_labels
from el.base.decision import Disc
from el.base.errors import LabelColourError, WeightsError
from el.classes.labels import UAVID, LabelClass, LabelSet, UavidClass, load_label_set
from el.geometry.config import CoreConfig
from el.landing.core import probs_from_labels, run_core
from el.landing.forbidden import forbidden_pixels
from el.monitors import CHMonitor, LHDMonitor, MCDMonitor, build_monitor, default_hierarchy
from el.monitors.base import validate_samples, validate_scores
from el.segmentation.inference import Segmenter

GRASS, GRAVEL, ROAD, WATER = 0, 1, 2, 3
FIELDS = LabelSet("fields", (
    LabelClass(GRASS, "grass", (0, 160, 0), False, 0.0),
    LabelClass(GRAVEL, "gravel", (160, 160, 160), False, 1.0),
    LabelClass(ROAD, "road", (128, 64, 128), True, None),
    LabelClass(WATER, "water", (0, 0, 255), True, None),
))


def fields_dict() -> dict:
    return copy.deepcopy(FIELDS.to_dict())


def one_hot(ids: np.ndarray, labels: LabelSet, top: float = 0.9) -> np.ndarray:
    rest = (1.0 - top) / (labels.num_classes - 1)
    scores = np.full((labels.num_classes, *ids.shape), rest, np.float32)
    np.put_along_axis(scores, ids[None].astype(np.int64), top, axis=0)
    return scores


def disc_ids(shape: tuple[int, int], cx: float, cy: float, r: float, inside: int, outside: int) -> np.ndarray:
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    return np.where((yy + 0.5 - cy) ** 2 + (xx + 0.5 - cx) ** 2 <= r * r, inside, outside).astype(np.uint8)


# -- the default set ----------------------------------------------------------------------------------
def test_uavid_round_trips_through_dict_and_json():
    d = UAVID.to_dict()
    assert LabelSet.from_dict(d) == UAVID
    assert LabelSet.from_dict(json.loads(json.dumps(d))) == UAVID
    assert hash(LabelSet.from_dict(d)) == hash(UAVID)
    assert pickle.loads(pickle.dumps(UAVID)) == UAVID
    assert FIELDS != UAVID and LabelSet.from_dict(FIELDS.to_dict()) == FIELDS


def test_module_names_are_the_default_sets():
    assert lab.CLASSES is UAVID.classes and UavidClass is LabelClass
    assert lab.NUM_CLASSES == UAVID.num_classes == 8
    assert lab.CLASS_NAMES == UAVID.names and lab.CLASS_IDS == UAVID.ids
    assert lab.FORBIDDEN_IDS == UAVID.forbidden_ids == (1, 2, 3, 7)
    assert lab.SAFE_IDS == UAVID.safe_ids == (0, 4, 5, 6)
    assert lab.PALETTE is UAVID.palette and lab.FORBIDDEN_LUT is UAVID.forbidden_lut
    assert lab.HAZARD_SCORES is UAVID.hazard_scores and lab.MAX_HAZARD_SCORE == UAVID.max_hazard_score == 3.0
    assert not UAVID.palette.flags.writeable  # a frozen set's tables cannot be changed under it
    ids = np.arange(8, dtype=np.uint8).reshape(2, 4)
    np.testing.assert_array_equal(lab.ids_to_colors(ids), UAVID.ids_to_colors(ids))
    np.testing.assert_array_equal(lab.colors_to_ids(lab.ids_to_colors(ids)), ids)
    np.testing.assert_array_equal(lab.forbidden_mask(ids), UAVID.forbidden_mask(ids))


def test_uavid_hierarchy_is_the_shipped_file():
    assert default_hierarchy(UAVID) is default_hierarchy(labels=UAVID)
    assert default_hierarchy(labels=UAVID).labels is UAVID


# -- a malformed set is refused, naming the problem -----------------------------------------------------
def _broken(change):
    d = fields_dict()
    change(d)
    return d


def _set(d, k, v):
    d[k] = v


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: _set(d["classes"][3], "rgb", [160, 160, 160]),
     r"'gravel' and 'water' share the colour RGB\(160, 160, 160\)"),
    (lambda d: d["classes"][2].pop("id"), r"class #2 \('road'\): missing id"),
    (lambda d: [_set(c, "forbidden", True) or c.pop("hazard_score", None) for c in d["classes"]], "no safe class"),
    (lambda d: [_set(c, "forbidden", False) or _set(c, "hazard_score", 0.0) for c in d["classes"]],
     "no forbidden class"),
    (lambda d: _set(d["classes"][3], "id", 2), r"duplicate ids \[2\]; missing ids \[3\]"),
    (lambda d: _set(d["classes"][3], "id", 7), r"missing ids \[3\]; ids out of range \[7\]"),
    (lambda d: _set(d["classes"][1], "name", "grass"), r"duplicate class names \['grass'\]"),
    (lambda d: d["classes"][1].pop("hazard_score"), "safe class 'gravel' needs a hazard score"),
    (lambda d: _set(d["classes"][1], "hazard_score", -1.0), "'gravel': hazard score must be a finite number >= 0"),
    (lambda d: _set(d["classes"][1], "hazard_score", float("nan")), "finite number >= 0"),
    (lambda d: _set(d["classes"][2], "hazard_score", 1.0), "'road' is forbidden and must have no hazard score"),
    (lambda d: _set(d["classes"][0], "rgb", [0, 300, 0]), r"'grass': rgb must be 3 integers in 0..255"),
    (lambda d: _set(d["classes"][0], "rgb", [0, 0]), "rgb must be 3 integers"),
    (lambda d: _set(d["classes"][0], "forbidden", "no"), "forbidden must be true or false"),
    (lambda d: _set(d["classes"][0], "colour", [1, 2, 3]), r"unknown keys \['colour'\]"),
    (lambda d: _set(d, "classes", []), "has no classes"),
    (lambda d: _set(d, "name", ""), "name must be a non-empty string"),
    (lambda d: d.pop("classes"), "needs 'name' and 'classes'"),
    (lambda d: _set(d, "colours", {}), r"unknown label set keys \['colours'\]"),
    (lambda d: _set(d, "hierarchy", {"root": "any", "children": {"any": ["grass", "gravel", "road"]}}),
     r"hierarchy: classes missing from the hierarchy: \['water'\]"),
    (lambda d: _set(d, "hierarchy", {"root": "any"}), "hierarchy: needs 'root: NAME' and 'children"),
])
def test_malformed_set_is_refused_with_a_clear_message(change, message):
    with pytest.raises(ValueError, match=message):
        LabelSet.from_dict(_broken(change))


def test_construction_checks_too():
    with pytest.raises(ValueError, match="listed in id order"):
        LabelSet("x", tuple(reversed(FIELDS.classes)))
    with pytest.raises(ValueError, match="at least one is needed"):
        LabelSet("x", (LabelClass(0, "a", (1, 2, 3), False, 0.0),))


def test_load_label_set_from_yaml_and_json(tmp_path):
    (tmp_path / "tree.yaml").write_text(
        "root: all\nchildren:\n  all: [dry, wet]\n  dry: [grass, gravel, road]\n  wet: [water]\n")
    y = tmp_path / "fields.yaml"
    y.write_text("name: fields\nhierarchy: tree.yaml\nclasses:\n"
                 "  - {id: 3, name: water, rgb: [0, 0, 255], forbidden: true}\n"
                 "  - {id: 0, name: grass, rgb: [0, 160, 0], forbidden: false, hazard_score: 0}\n"
                 "  - {id: 1, name: gravel, rgb: [160, 160, 160], forbidden: false, hazard_score: 1}\n"
                 "  - {id: 2, name: road, rgb: [128, 64, 128], forbidden: true}\n")
    loaded = load_label_set(y)
    assert loaded.names == FIELDS.names and loaded.classes == FIELDS.classes
    assert loaded.hierarchy == {"root": "all", "children": {"all": ["dry", "wet"], "dry": ["grass", "gravel", "road"],
                                                            "wet": ["water"]}}
    h = default_hierarchy(loaded)
    assert h.nodes[h.root] == "all" and set(h.rejected_names) == {"all", "dry", "wet", "road", "water"}
    j = tmp_path / "fields.json"
    j.write_text(json.dumps(FIELDS.to_dict()))
    assert load_label_set(j) == FIELDS
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_broken(lambda d: d["classes"][2].pop("id"))))
    with pytest.raises(ValueError, match=r"bad\.json: class #2 \('road'\): missing id"):
        load_label_set(bad)
    with pytest.raises(ValueError, match="cannot read label set"):
        load_label_set(tmp_path / "missing.yaml")


# -- colours --------------------------------------------------------------------------------------------
def test_colours_use_the_sets_palette(tmp_path):
    ids = np.array([[GRASS, GRAVEL], [ROAD, WATER]], np.uint8)
    rgb = FIELDS.ids_to_colors(ids)
    assert rgb[1, 1].tolist() == [0, 0, 255] and rgb[0, 1].tolist() == [160, 160, 160]
    np.testing.assert_array_equal(FIELDS.colors_to_ids(rgb), ids)
    np.testing.assert_array_equal(FIELDS.forbidden_mask(ids), [[False, False], [True, True]])
    with pytest.raises(LabelColourError, match=r"not 'fields' classes: RGB\(0,0,0\) x 1 px"):
        FIELDS.colors_to_ids(UAVID.ids_to_colors(np.array([[0]], np.uint8)))  # UAVid's clutter
    with pytest.raises(ValueError, match=r"0\.\.3"):
        FIELDS.ids_to_colors(np.array([[4]]))
    big = np.kron(ids, np.ones((8, 8), np.uint8))
    write_labels(tmp_path / "l.png", big, FIELDS)
    np.testing.assert_array_equal(read_labels(tmp_path / "l.png", FIELDS), big)
    with pytest.raises(LabelColourError):
        read_labels(tmp_path / "l.png", labels=UAVID)  # the default set does not know these colours


# -- the core model with another set --------------------------------------------------------------------
def fields_scene() -> np.ndarray:
    """256x144: road on the left, grass in the middle, gravel on the right with a pond of water in it."""
    ids = np.full((144, 256), GRASS, np.uint8)
    ids[:, :96] = ROAD
    ids[:, 176:] = GRAVEL
    ids[100:120, 200:230] = WATER
    return ids


def test_run_core_with_another_set_keeps_clear_of_its_forbidden_classes():
    ids = fields_scene()
    probs = probs_from_labels(ids, (128, 72), labels=FIELDS)
    assert probs.shape == (4, 72, 128)
    result = run_core(probs, (256, 144), CoreConfig(working_width=128), labels=FIELDS)
    assert result.candidates
    for c in result.candidates:
        pix = disc_pixels(ids, Disc(c.x, c.y, c.radius_px))
        assert pix.size and not FIELDS.forbidden_lut[pix].any()
        assert c.x - c.radius_px >= 96
    best = result.candidates[0]
    assert ids[int(best.y), int(best.x)] == GRASS and best.hazard_semantic == 0.0  # grass scores 0, gravel 1
    on_gravel = [c for c in result.candidates if c.x - c.radius_px > 176]
    assert on_gravel and all(c.hazard_semantic == 1.0 for c in on_gravel)
    with pytest.raises(ValueError, match=r"shape \(8, h, w\)"):
        run_core(probs, (256, 144), CoreConfig(working_width=128), labels=UAVID)  # 4 classes are not UAVid's 8


def test_ground_truth_decision_with_another_set():
    ids = fields_scene()
    decision = decide_from_labels(ids, config=CoreConfig(working_width=128), labels=FIELDS)
    assert decision.action == "land"
    sel = decision.candidates[decision.selected]
    assert true_hazard(ids, Disc(sel.x, sel.y, sel.radius_px), labels=FIELDS) == 0.0
    assert true_hazard(ids, Disc(40.0, 70.0, 10.0), labels=FIELDS) == 1.0  # on the road
    assert true_hazard(ids, Disc(190.0, 40.0, 8.0), labels=FIELDS) == 0.5  # all gravel: (1 - kappa) * 1
    ids[ids == GRASS] = ROAD
    ids[ids == GRAVEL] = WATER
    assert decide_from_labels(ids, config=CoreConfig(working_width=128), labels=FIELDS).reason == "no_candidate"


# -- monitors with another set --------------------------------------------------------------------------
@pytest.mark.parametrize("spec", ["lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=4,rho=0.9", "lhd+ch+mcd:tau=0.25,n=4,rho=0.9",
                                  "msp", "entropy", "energy"])
def test_monitors_with_another_set_reject_a_disc_of_its_forbidden_class(spec):
    monitor = build_monitor(spec, labels=FIELDS)
    assert monitor.labels is FIELDS
    shape = (25, 25)
    mask = disc_ids(shape, 12.5, 12.5, 10.0, 1, 0).astype(bool)
    clean = one_hot(np.full(shape, GRASS, np.uint8), FIELDS, top=0.97)
    pond = one_hot(disc_ids(shape, 12.5, 12.5, 4.0, WATER, GRASS), FIELDS, top=0.97)
    if isinstance(monitor, MCDMonitor):
        clean, pond = np.repeat(clean[None], 4, axis=0), np.repeat(pond[None], 4, axis=0)
    assert monitor.check_scores(clean, mask).accepted
    verdict = monitor.check_scores(pond, mask)
    assert not verdict.accepted
    if spec.startswith("lhd"):
        assert "water" in verdict.reason
    with pytest.raises(ValueError, match="shape"):
        monitor.check_scores(np.repeat(clean, 2, axis=-3), mask)  # 8 classes, not the set's 4


class FieldsSegmenter:
    """A perfect segmenter for images painted in the FIELDS palette."""

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        return one_hot(FIELDS.colors_to_ids(rgb_patch), FIELDS)

    def mc_dropout(self, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int) -> np.ndarray:
        return np.repeat(self.predict_patch(rgb_patch)[None], n, axis=0)


def test_lhd_with_another_set_checks_a_candidate_on_an_image():
    ids = np.full((96, 96), GRASS, np.uint8)
    image = FIELDS.ids_to_colors(disc_ids(ids.shape, 30.0, 30.0, 5.0, WATER, GRASS))
    lhd = LHDMonitor(labels=FIELDS)
    wet = lhd.check(image, Disc(30.0, 30.0, 12.0), FieldsSegmenter())
    assert not wet.accepted and wet.reason.startswith("forbidden class in disc: water (")
    assert lhd.check(image, Disc(70.0, 70.0, 12.0), FieldsSegmenter()).accepted
    assert not forbidden_pixels(one_hot(ids, FIELDS), FIELDS).any()


def test_ch_hierarchy_must_match_the_monitors_set():
    assert CHMonitor(tau=0.25, labels=FIELDS).hierarchy.nodes == ("grass", "gravel", "road", "water", "any", "safe",
                                                                  "unsafe")
    with pytest.raises(ValueError, match="label set 'uavid'"):
        CHMonitor(tau=0.25, labels=FIELDS, hierarchy=default_hierarchy(labels=UAVID))
    taken = LabelSet("odd", (LabelClass(0, "safe", (1, 1, 1), False, 0.0), LabelClass(1, "b", (2, 2, 2), True, None)))
    assert CHMonitor(tau=0.25, labels=taken).hierarchy.nodes == ("safe", "b", "any", "safe_node", "unsafe")


def test_validation_takes_the_class_count_from_the_set_or_the_array():
    scores = np.full((4, 3, 3), 0.25, np.float32)
    assert validate_scores(scores, (3, 3), labels=FIELDS) is scores
    assert validate_scores(scores, (3, 3), labels=None) is scores
    with pytest.raises(ValueError, match=r"\(8, 3, 3\)"):
        validate_scores(scores, (3, 3), labels=UAVID)
    samples = np.repeat(scores[None], 2, axis=0)
    assert validate_samples(samples, (3, 3), 2, labels=FIELDS) is samples
    assert validate_samples(samples, (3, 3), 2, labels=None) is samples
    with pytest.raises(ValueError, match=r"\(n, 8, 3, 3\)"):
        validate_samples(samples, (3, 3), 2, labels=UAVID)


# -- the segmenter ----------------------------------------------------------------------------------------
class FourClassNet(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.conv = nn.Conv2d(3, 4, 1)
        self.drop = nn.Dropout2d(0.5)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.drop(self.conv(x))


def test_segmenter_shapes_follow_its_label_set():
    torch.manual_seed(0)
    seg = Segmenter(FourClassNet(), working_width=32, labels=FIELDS)
    assert seg.labels is FIELDS
    rgb = np.random.default_rng(0).integers(0, 256, (36, 64, 3), dtype=np.uint8)
    assert seg.predict_frame(rgb).shape == (4, 18, 32)
    assert seg.predict_patch(rgb[:20, :20]).shape == (4, 20, 20)
    assert seg.mc_dropout(rgb[:20, :20], 3, 0.9, 0).shape == (3, 4, 20, 20)
    assert pickle.loads(pickle.dumps(seg)).labels == FIELDS
    with pytest.raises(ValueError, match=r"expected logits of shape \(1, 8, 20, 20\)"):
        Segmenter(FourClassNet(), working_width=32, labels=UAVID).predict_patch(rgb[:20, :20])
    with pytest.raises(ValueError, match="LabelSet"):
        Segmenter(FourClassNet(), labels=FIELDS.to_dict())  # type: ignore[arg-type]


def test_segmenter_load_takes_the_set_from_the_model_card(tmp_path):
    from assurance.fitting.network.weights_io import save_weights
    from el.segmentation.architectures import build_model
    from el.segmentation.model import ArchConfig

    torch.manual_seed(0)
    model = build_model(ArchConfig(widths=(8, 8, 8), decoder_channels=8))
    renamed = {**UAVID.to_dict(), "name": "uavid-relabelled"}
    save_weights(model, tmp_path / "with.pt", {"labels": renamed})
    save_weights(model, tmp_path / "without.pt")
    assert Segmenter.load(tmp_path / "with.pt").labels == LabelSet.from_dict(renamed)
    assert Segmenter.load(tmp_path / "without.pt").labels is UAVID
    save_weights(model, tmp_path / "bad.pt", {"labels": {**renamed, "classes": renamed["classes"][:1]}})
    with pytest.raises(WeightsError, match=r"bad\.json: model card 'labels': .*no forbidden class"):
        Segmenter.load(tmp_path / "bad.pt")


def test_build_monitor_refuses_a_set_for_a_plugin_that_takes_none():
    from el.monitors.registry import register_monitor, unregister_monitor

    def factory(*, margin, max_side, clock, threshold):  # an older plugin: no labels keyword
        raise AssertionError("not reached with a label set")

    register_monitor("nolabels", factory)
    try:
        from el.monitors.capabilities import MonitorSupportError

        with pytest.raises(MonitorSupportError, match="'nolabels' .* does not take a label set"):  # at build
            build_monitor("nolabels", labels=FIELDS)
    finally:
        unregister_monitor("nolabels")
    assert build_monitor("msp", labels=FIELDS).labels is FIELDS
