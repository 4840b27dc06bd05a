"""Label sets as data: the packaged presets (UAVid, the Semantic Drone Dataset), the compact palette form and
its checks (docs/architecture.md section 2.1)."""

from __future__ import annotations

import numpy as np
import pytest

from assurance.campaign.truth import true_hazard
from assurance.dataio.uavid import read_labels, write_image, write_labels
from el.base.decision import Disc
from el.classes.labels import PRESET_DIR, UAVID, LabelSet, label_presets, load_label_set

SD_FORBIDDEN = {"paved-area", "water", "pool", "roof", "wall", "window", "door", "fence", "fence-pole", "person",
                "dog", "car", "bicycle", "obstacle", "conflicting"}


def test_uavid_preset_is_the_shipped_set_and_its_file_says_the_same():
    assert {"uavid", "semantic_drone"} <= set(label_presets())
    assert load_label_set("uavid") is UAVID
    from_file = load_label_set(PRESET_DIR / "uavid.yaml")
    assert from_file == UAVID and from_file.to_dict() == UAVID.to_dict()
    assert np.array_equal(from_file.hazard_scores, UAVID.hazard_scores)


def test_unknown_preset_names_the_presets():
    with pytest.raises(ValueError, match=r"'cityscapes' is neither a label set preset \(semantic_drone, uavid\)"):
        load_label_set("cityscapes")
    with pytest.raises(ValueError, match="cannot read label set"):
        load_label_set("no/such/file.yaml")


def test_semantic_drone_preset_classes_colours_and_categories():
    sd = load_label_set("semantic_drone")
    assert sd.num_classes == 23 and sd.ignore is not None
    assert (sd.ignore.rgb, sd.ignore.id, sd.ignore.counts_as, sd.ignore.name) == ((0, 0, 0), 255, "forbidden",
                                                                                 "unlabeled")
    assert {sd.names[i] for i in sd.forbidden_ids} == SD_FORBIDDEN  # people, dogs, bicycles, cars, roads included
    scores = {c.name: c.hazard_score for c in sd.classes if not c.forbidden}
    assert scores == {"dirt": 1.0, "grass": 0.0, "gravel": 1.0, "rocks": 2.0, "vegetation": 2.0, "tree": 3.0,
                      "bald-tree": 3.0, "ar-marker": 2.0}
    # the data set's class_dict colours (spot checks), ids in its order without "unlabeled"
    colours = {c.name: c.rgb for c in sd.classes}
    assert colours["paved-area"] == (128, 64, 128) and colours["person"] == (255, 22, 96)
    assert colours["car"] == (9, 143, 150) and colours["conflicting"] == (255, 0, 0)
    assert sd.names[0] == "paved-area" and sd.names[-1] == "conflicting"
    assert LabelSet.from_dict(sd.to_dict()) == sd


def test_a_semantic_drone_label_png_with_unlabelled_pixels_reads_correctly(tmp_path):
    sd = load_label_set("semantic_drone")
    rgb = np.zeros((6, 8, 3), np.uint8)  # unlabeled everywhere ...
    rgb[:, 4:] = (0, 102, 0)  # ... but grass on the right
    rgb[0, 7] = (255, 22, 96)  # a person
    rgb[5, 0] = (128, 64, 128)  # paved area
    write_image(tmp_path / "l.png", rgb)
    ids = read_labels(tmp_path / "l.png", sd)
    assert ids.dtype == np.uint8
    assert (ids[:, :4][(ids[:, :4] != 0)] == 255).all() and ids[5, 0] == sd.ids["paved-area"]
    assert ids[0, 7] == sd.ids["person"] and (ids[1:, 4:] == sd.ids["grass"]).all()
    assert sd.forbidden_mask(ids)[:, :4].all()  # unknown ground and paved area
    assert sd.forbidden_mask(ids)[0, 7] and not sd.forbidden_mask(ids)[1:, 4:].any()
    write_labels(tmp_path / "back.png", ids, sd)
    np.testing.assert_array_equal(read_labels(tmp_path / "back.png", sd), ids)
    with pytest.raises(ValueError, match="not UAVid classes"):
        read_labels(tmp_path / "l.png", labels=UAVID)  # UAVid does not know these colours


def test_truth_of_a_semantic_drone_disc():
    sd = load_label_set("semantic_drone")
    ids = np.full((40, 40), sd.ids["grass"], np.uint8)
    assert true_hazard(ids, Disc(20.0, 20.0, 5.0), labels=sd) == 0.0
    ids[20, 24] = sd.ids["person"]
    assert true_hazard(ids, Disc(20.0, 20.0, 5.0), labels=sd) == 1.0  # a disc touching a person is unsafe
    ids[20, 24] = 255
    assert true_hazard(ids, Disc(20.0, 20.0, 5.0), labels=sd) == 1.0  # and one touching unknown ground
    ids[:] = sd.ids["tree"]
    assert true_hazard(ids, Disc(20.0, 20.0, 5.0), labels=sd) == 0.5  # (1 - kappa) * 3 / 3


def test_palette_form_and_its_errors_name_key_and_value(tmp_path):
    base = {"name": "fields", "palette": {"grass": [0, 160, 0], "road": [128, 64, 128], "tree": [0, 90, 0]},
            "forbidden": ["road"], "hazard_scores": {"grass": 0, "tree": 3}}
    s = LabelSet.from_dict(base)
    assert s.names == ("grass", "road", "tree") and s.forbidden_ids == (1,) and s.hazard_scores.tolist() == [0, 0, 3]
    bad = [
        ({"palette": {**base["palette"], "tree": [0, 160, 0]}}, r"palette.tree: RGB\(0, 160, 0\) is already the "
                                                                 r"colour of 'grass'"),
        ({"forbidden": ["road", "person"]}, r"forbidden: 'person' is not a class of the palette"),
        ({"hazard_scores": {"grass": 0}}, r"hazard_scores: safe classes \['tree'\] need a score"),
        ({"hazard_scores": {"grass": 0, "tree": 3, "road": 1}}, "hazard_scores.road: 'road' is forbidden"),
        ({"hazard_scores": {"grass": 0, "tree": 3, "lake": 1}}, "hazard_scores.lake: not a class"),
        ({"palette": {"grass": [0, 160]}}, r"palette.grass: must be 3 integers in 0..255, got \[0, 160\]"),
        ({"ignore": {"rgb": [0, 160, 0]}}, r"ignore.rgb: RGB\(0, 160, 0\) is already the colour of class 'grass'"),
        ({"ignore": {"rgb": [1, 1, 1], "id": 2}}, r"ignore.id: must be an integer in 3..255 .* got 2"),
        ({"ignore": {"rgb": [1, 1, 1], "counts_as": "safe"}}, "ignore.counts_as: must be one of forbidden, excluded"),
        ({"ignore": {"rgb": [1, 1, 1], "colour": 1}}, r"ignore: unknown keys \['colour'\]"),
        ({"ignore": {"rgb": [1, 1, 1], "name": "grass"}}, "ignore.name: 'grass' is already a class name"),
        ({"classes": []}, "not both"),
    ]
    for change, message in bad:
        with pytest.raises(ValueError, match=message):
            LabelSet.from_dict({**base, **change})
    path = tmp_path / "f.yaml"
    path.write_text("name: f\npalette: {a: [1, 2, 3], b: [1, 2, 3]}\nforbidden: [b]\nhazard_scores: {a: 0}\n")
    with pytest.raises(ValueError, match=r"f.yaml: palette.b: RGB\(1, 2, 3\) is already the colour of 'a'"):
        load_label_set(path)


def test_an_ignore_colour_added_to_a_set():
    white = UAVID.with_ignore((255, 255, 255))
    assert white != UAVID and white.ignore_id == 255 and UAVID.ignore is None
    rgb = UAVID.ids_to_colors(np.array([[2, 5]], np.uint8))
    rgb = np.concatenate([rgb, np.full((1, 1, 3), 255, np.uint8)], axis=1)
    ids = white.colors_to_ids(rgb)
    assert ids.tolist() == [[2, 5, 255]]
    assert white.forbidden_mask(ids).tolist() == [[True, False, True]]
    assert white.ignored_mask(ids).tolist() == [[False, False, True]]
    assert white.planning_ids(ids).tolist() == [[2, 5, UAVID.forbidden_ids[0]]]
    np.testing.assert_array_equal(white.ids_to_colors(ids), rgb)
    with pytest.raises(ValueError, match="0..7, got 2..255"):
        UAVID.ids_to_colors(ids)  # no ignore colour: 255 is no id
    with pytest.raises(ValueError, match="0..7 or the ignore id 255, got 2..254"):
        white.ids_to_colors(np.array([[2, 254]], np.uint8))
    with pytest.raises(ValueError, match=r"ignore.rgb: RGB\(0, 0, 0\) is already the colour of class 'clutter'"):
        UAVID.with_ignore((0, 0, 0))
    assert LabelSet.from_dict(white.to_dict()) == white


def test_excluded_ignored_pixels_leave_the_disc():
    ex = UAVID.with_ignore((255, 255, 255), counts_as="excluded")
    ids = np.full((40, 40), UAVID.ids["tree"], np.uint8)
    ids[:, :20] = 255
    assert ex.forbidden_mask(np.array([255])).tolist() == [False]
    assert true_hazard(ids, Disc(20.0, 20.0, 5.0), labels=ex) == 0.5 * 3 / 3  # the tree half only
    assert true_hazard(ids, Disc(8.0, 20.0, 5.0), labels=ex) == 1.0  # nothing known: unsafe
    assert true_hazard(ids, Disc(20.0, 20.0, 5.0), labels=UAVID.with_ignore((255, 255, 255))) == 1.0


def test_planning_on_labels_with_unknown_ground_keeps_clear_of_it():
    """What the ground-truth pipeline needs: ignored pixels planned on as forbidden (``planning_ids``)."""
    from assurance.campaign.gt_pipeline import decide_from_labels
    from assurance.campaign.truth import disc_pixels
    from el.geometry.config import CoreConfig

    sd = load_label_set("semantic_drone")
    ids = np.full((144, 256), sd.ids["grass"], np.uint8)
    ids[:, 100:180] = 255  # a wide unlabelled band
    raw = decide_from_labels(ids, config=CoreConfig(working_width=128), labels=sd)  # the pipeline plans them too
    decision = decide_from_labels(sd.planning_ids(ids), config=CoreConfig(working_width=128), labels=sd)
    assert [(c.x, c.y) for c in raw.candidates] == [(c.x, c.y) for c in decision.candidates]
    assert decision.action == "land" and decision.candidates
    for c in decision.candidates:
        assert not (disc_pixels(ids, Disc(c.x, c.y, c.radius_px)) == 255).any()
        assert true_hazard(ids, Disc(c.x, c.y, c.radius_px), labels=sd) == 0.0
