"""The class map (el.segmentation.class_map.MappedModel): a network's classes summed onto the system's label set."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from helpers import TINY_ARCH, OracleSegmenter, scene_ids

from el.classes.labels import UAVID, LabelSet, ids_to_colors
from el.monitors.patches import accepts_keyword
from el.segmentation.architectures import build_model
from el.segmentation.class_map import MappedModel, check_class_map, map_probabilities
from el.segmentation.contract import MC_DROPOUT, PATCH_TRUNK, TRUNK_FEATURES, SegmentationModel, has_capability
from el.segmentation.inference import Segmenter

COARSE = LabelSet.from_dict({
    "name": "coarse",
    "palette": {"ground": [0, 200, 0], "vehicle": [0, 0, 200], "built": [200, 0, 0], "water": [0, 0, 90]},
    "forbidden": ["vehicle", "built", "water"], "hazard_scores": {"ground": 0},
})
TO_COARSE = {"clutter": "ground", "building": "built", "road": "built", "static_car": "vehicle", "tree": "ground",
             "low_vegetation": "ground", "human": "ground", "moving_car": "vehicle"}
REVERSED = LabelSet("reversed", tuple(type(c)(7 - c.id, c.name.upper(), c.rgb, c.forbidden, c.hazard_score)
                                      for c in reversed(UAVID.classes)))
TO_REVERSED = {n: n.upper() for n in UAVID.names}


@pytest.fixture(scope="module")
def frame():
    return ids_to_colors(scene_ids(128, 72, seed=1))


def test_a_renaming_gives_the_same_probabilities_reordered_exactly(frame):
    oracle = OracleSegmenter(64)
    mapped = MappedModel(oracle, TO_REVERSED, REVERSED)
    assert isinstance(mapped, SegmentationModel) and mapped.labels is REVERSED
    assert mapped.weights_sha256 == oracle.weights_sha256
    np.testing.assert_array_equal(mapped.predict_frame(frame), oracle.predict_frame(frame)[::-1])
    np.testing.assert_array_equal(mapped.predict_patch(frame[:20, :30]), oracle.predict_patch(frame[:20, :30])[::-1])
    samples = mapped.mc_dropout(frame[:20, :30], 3, 0.9, 7)
    np.testing.assert_array_equal(samples, oracle.mc_dropout(frame[:20, :30], 3, 0.9, 7)[:, ::-1])


def test_many_to_one_sums_and_an_unreachable_class_is_zero(frame):
    mapped = MappedModel(OracleSegmenter(64), TO_COARSE, COARSE, unreachable=["water"])
    p, q = OracleSegmenter(64).predict_frame(frame), mapped.predict_frame(frame)
    assert q.shape == (4, *p.shape[1:]) and q.dtype == np.float32
    np.testing.assert_allclose(q[COARSE.ids["built"]], p[UAVID.ids["building"]] + p[UAVID.ids["road"]])
    np.testing.assert_allclose(q[COARSE.ids["ground"]], p[list(UAVID.safe_ids)].sum(axis=0), rtol=1e-6)
    assert not q[COARSE.ids["water"]].any()
    np.testing.assert_allclose(q.sum(axis=0), 1.0, rtol=1e-6)


@pytest.mark.parametrize(("mapping", "unreachable", "message"), [
    ({k: v for k, v in TO_COARSE.items() if k != "human"}, ["water"],
     "network class 'human' is not mapped onto a system class"),
    ({**TO_COARSE, "human": "person"}, ["water"], "'human' -> 'person': 'person' is not a class of the system's"),
    ({**TO_COARSE, "boat": "water"}, [], "'boat' is not a class of the network's label set 'uavid'"),
    (TO_COARSE, [], "system class 'water' is reached by no network class"),
    (TO_COARSE, ["water", "built"], r"'built' is listed unreachable but \['building', 'road'\] map onto it"),
    (TO_COARSE, ["lake"], "unreachable 'lake' is not a class"),
])
def test_a_bad_map_names_the_class(mapping, unreachable, message):
    with pytest.raises(ValueError, match=message):
        MappedModel(OracleSegmenter(64), mapping, COARSE, unreachable=unreachable)


def test_wrong_class_count_from_the_network_is_refused():
    target = check_class_map(UAVID, COARSE, TO_COARSE, ["water"])
    with pytest.raises(ValueError, match="expected 8 classes"):
        map_probabilities(np.zeros((5, 2, 2), np.float32), target, 4)


def test_capabilities_pass_through_only_where_the_network_has_them(frame):
    class FrameOnly:
        def predict_frame(self, rgb):
            return OracleSegmenter(64).predict_frame(rgb)

        def predict_patch(self, rgb):
            return OracleSegmenter(64).predict_patch(rgb)

    bare = MappedModel(FrameOnly(), TO_REVERSED, REVERSED)
    assert not any(has_capability(bare, c) for c in (MC_DROPOUT, PATCH_TRUNK, TRUNK_FEATURES))
    assert bare.weights_sha256 is None
    with pytest.raises(AttributeError, match="offers no mc_dropout"):
        bare.mc_dropout(frame, 2, 0.9, 0)
    oracle = MappedModel(OracleSegmenter(64), TO_REVERSED, REVERSED)
    assert has_capability(oracle, MC_DROPOUT) and not has_capability(oracle, PATCH_TRUNK)
    assert not accepts_keyword(oracle.mc_dropout, "window")  # the oracle takes no window: nor does its map


def test_the_built_in_network_through_the_map(frame):
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH).eval(), working_width=64, labels=UAVID)
    mapped = MappedModel(seg, TO_REVERSED, REVERSED)
    assert all(has_capability(mapped, c) for c in (MC_DROPOUT, PATCH_TRUNK, TRUNK_FEATURES))
    assert accepts_keyword(mapped.mc_dropout, "window") and mapped.working_size(128, 72) == seg.working_size(128, 72)
    patch = frame[:32, :48]
    trunk = mapped.patch_trunk(patch)
    np.testing.assert_array_equal(mapped.predict_patch(patch, features=trunk), seg.predict_patch(patch)[::-1])
    a = mapped.mc_dropout(patch, 4, 0.9, 3, features=trunk, window=(2, 10, 4, 20))
    b = seg.mc_dropout(patch, 4, 0.9, 3, window=(2, 10, 4, 20))
    np.testing.assert_array_equal(a, b[:, ::-1])
    np.testing.assert_array_equal(mapped.predict_frame(frame), seg.predict_frame(frame)[::-1])
    again = pickle.loads(pickle.dumps(mapped))
    np.testing.assert_array_equal(again.predict_frame(frame), mapped.predict_frame(frame))
    assert again.labels == REVERSED and again.mapping == TO_REVERSED
