"""Issue 57, show don't trust the words: the report's first page shows, for each safe class, frames of the run's own
data with that class's pixels tinted, so a 'meadow' painted over asphalt is seen, whatever its name says."""

from __future__ import annotations

import base64

import cv2
import numpy as np
import pytest
from conftest import tiny_scene

from assurance.dataio.layouts import iter_samples
from assurance.dataio.uavid import write_sample
from assurance.evidence.safe_strips import TINT, evenly_spaced, safe_class_strips, tint
from el.classes.labels import UAVID, LabelSet


def _meadow_over_road() -> LabelSet:
    """UAVid with road renamed 'meadow', declared safe (vegetation) in road's colour: what the review flew."""
    d = UAVID.to_dict()
    road = next(c for c in d["classes"] if c["name"] == "road")
    road.update(name="meadow", forbidden=False, hazard_score=0.0, category="vegetation")
    return LabelSet.from_dict(d)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("strips")
    for i in range(5):
        ids = tiny_scene(i)
        write_sample(root, "seq00", f"{i:06d}", UAVID.ids_to_colors(ids), ids, labels=UAVID)
    return {s.key: s for s in iter_samples(root)}


def _decode(uri: str) -> np.ndarray:
    raw = base64.b64decode(uri.split(",", 1)[1])
    return cv2.cvtColor(cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def test_one_strip_per_safe_class_with_the_frames_where_it_covers_most(data):
    out = safe_class_strips(data, sorted(data), UAVID, per_class=2, width=128)
    assert [s["name"] for s in out["strips"]] == [UAVID.names[i] for i in UAVID.safe_ids]
    assert out["frames"] == 5 and "5 frame(s)" in out["note"]
    veg = next(s for s in out["strips"] if s["name"] == "low_vegetation")
    assert len(veg["frames"]) == 2 and veg["category"] == "vegetation" and veg["hazard"] == "0"
    human = next(s for s in out["strips"] if s["name"] == "human")
    assert human["frames"] == [] and human["share"] == "0.0%"  # the tiny scenes hold no person: said, not drawn
    again = safe_class_strips(data, sorted(data), UAVID, per_class=2, width=128)
    assert again == out  # deterministic: same frames, same bytes


def test_a_meadow_painted_over_road_is_seen_tinted_where_the_road_is(data):
    """The label maps are UAVid's; read with the applicant's set, road's pixels are 'meadow'. Its strip tints exactly
    the road stripe of each frame: the magenta lies where the road is."""
    labels = _meadow_over_road()
    out = safe_class_strips(data, sorted(data), labels, per_class=1, width=256)
    meadow = next(s for s in out["strips"] if s["name"] == "meadow")
    (frame,) = meadow["frames"]
    picture = _decode(frame["uri"]).astype(int)
    ids = UAVID.colors_to_ids(cv2.cvtColor(cv2.imread(str(data[frame["key"]].label_path)), cv2.COLOR_BGR2RGB))
    road = cv2.resize((ids == 2).astype(np.uint8), picture.shape[1::-1], interpolation=cv2.INTER_NEAREST) > 0
    inner = cv2.erode(road.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0  # away from JPEG edges
    magenta = (picture[..., 0] > picture[..., 1] + 60) & (picture[..., 2] > picture[..., 1] + 60)
    assert magenta[inner].mean() > 0.95 and magenta[~road].mean() < 0.02


def test_tint_marks_the_mask_and_greys_the_rest():
    image = np.full((4, 4, 3), (0, 200, 0), np.uint8)
    mask = np.zeros((4, 4), bool)
    mask[:2] = True
    out = tint(image, mask)
    assert (out[:2] == np.array([0.5 * TINT[0], 100 + 0.5 * TINT[1], 0.5 * TINT[2]]).round()).all()
    assert (out[2:, :, 0] == out[2:, :, 1]).all() and (out[2:, :, 1] == out[2:, :, 2]).all()  # grey


def test_frames_are_spread_over_the_run_and_unreadable_ones_are_passed_over(data, tmp_path):
    assert evenly_spaced([f"k{i}" for i in range(10)], 3) == ["k0", "k4", "k9"]
    assert evenly_spaced(["b", "a"], 8) == ["a", "b"]
    out = safe_class_strips({}, ["seq00/missing"], UAVID)
    assert out["frames"] == 0 and "could be read" in out["note"] and all(not s["frames"] for s in out["strips"])


def test_a_strip_says_the_category_the_basis_judges_by(data):
    """A synonym of road declared safe as vegetation: its strip says road, pinned, and what the set declared."""
    d = UAVID.to_dict()
    next(c for c in d["classes"] if c["name"] == "road").update(name="Stra\u00dfe", forbidden=False, hazard_score=0.0,
                                                                 category="vegetation")
    out = safe_class_strips(data, sorted(data), LabelSet.from_dict(d), per_class=1, width=64)
    cats = {s["name"]: s["category"] for s in out["strips"]}
    assert cats["Stra\u00dfe"] == "road, pinned; declared vegetation" and cats["clutter"] == "unknown"
