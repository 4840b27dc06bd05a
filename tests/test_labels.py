"""Label table and colour <-> class-id conversion (docs/architecture.md section 2.1)."""

import numpy as np
import pytest

from el.classes.labels import (
    CLASSES,
    FORBIDDEN_IDS,
    HAZARD_SCORES,
    LabelColourError,
    colors_to_ids,
    forbidden_mask,
    ids_to_colors,
)


def test_table_matches_design():
    assert [c.name for c in CLASSES] == [
        "clutter", "building", "road", "static_car", "tree", "low_vegetation", "human", "moving_car",
    ]
    assert FORBIDDEN_IDS == (1, 2, 3, 7)
    assert CLASSES[2].rgb == (128, 64, 128)
    assert HAZARD_SCORES.tolist() == [2, 0, 0, 0, 3, 0, 1, 0]


def test_round_trip_all_classes():
    rng = np.random.default_rng(0)
    ids = rng.integers(0, 8, size=(37, 53)).astype(np.uint8)
    back = colors_to_ids(ids_to_colors(ids))
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, ids)


def test_unknown_colour_names_file_colour_and_count():
    rgb = ids_to_colors(np.zeros((4, 5), np.uint8))
    rgb[0, :3] = (1, 2, 3)
    with pytest.raises(LabelColourError) as err:
        colors_to_ids(rgb, source="seq1/Labels/000001.png")
    msg = str(err.value)
    assert "seq1/Labels/000001.png" in msg and "RGB(1,2,3)" in msg and "x 3 px" in msg


def test_forbidden_mask():
    ids = np.arange(8, dtype=np.uint8).reshape(2, 4)
    assert forbidden_mask(ids).ravel().tolist() == [False, True, True, True, False, False, False, True]


def test_ids_out_of_range_rejected():
    with pytest.raises(ValueError):
        ids_to_colors(np.array([[8]]))
