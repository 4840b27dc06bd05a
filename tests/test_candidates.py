"""Unit tests of the CM building blocks: pooling, valid pixels, regions, representatives, ranking."""

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from el.classes.labels import CLASS_IDS, NUM_CLASSES, UAVID
from el.geometry.camera import CameraGeometry, Pose, SafetyParams
from el.geometry.config import CoreConfig
from el.landing import candidates as cand
from el.landing import ranking
from el.landing import regions as reg
from el.landing import representatives as reps
from el.landing.core import check_probs, default_area, probs_from_labels, run_core

ROAD = CLASS_IDS["road"]
BUILDING = CLASS_IDS["building"]
CAR = CLASS_IDS["static_car"]
LOWVEG = CLASS_IDS["low_vegetation"]
TREE = CLASS_IDS["tree"]


# -- conservative pooling ------------------------------------------------------------------------
@pytest.mark.requirements("EL-R01")
@pytest.mark.parametrize(
    "size,working", [((256, 144), (128, 72)), ((300, 169), (128, 72)), ((3840, 2160), (1024, 576))]
)
@pytest.mark.parametrize("kind", ["horizontal", "vertical", "diagonal"])
def test_pooling_keeps_a_one_pixel_road(size, working, kind):
    W, H = size
    ids = np.full((H, W), LOWVEG, dtype=np.uint8)
    if kind == "horizontal":
        ids[H // 2 + 1, :] = ROAD
    elif kind == "vertical":
        ids[:, W // 2 + 1] = ROAD
    else:
        n = min(W, H)
        ids[np.arange(n), np.arange(n) + 1] = ROAD
    pooled = cand.pooled_label_ids(ids, working, labels=UAVID)
    assert pooled.shape == (working[1], working[0])
    # every road pixel lies under a working pixel that is road
    ry, rx = np.nonzero(ids == ROAD)
    wy = (ry * working[1]) // H
    wx = (rx * working[0]) // W
    assert (pooled[wy, wx] == ROAD).all()
    if kind == "horizontal":
        assert (pooled == ROAD).sum() == working[0]  # one full working row, no gap
        # the trap: nearest-neighbour sampling loses it
        nearest = cv2.resize(ids, working, interpolation=cv2.INTER_NEAREST)
        assert not (nearest == ROAD).any() or W % working[0]
    probs = probs_from_labels(ids, working, labels=UAVID)
    assert probs.dtype == np.float32 and probs.shape == (NUM_CLASSES, working[1], working[0])
    np.testing.assert_array_equal(probs.argmax(axis=0), pooled)
    np.testing.assert_array_equal(probs.sum(axis=0), 1.0)


def test_pooling_prefers_the_most_frequent_forbidden_class_and_safe_majority():
    ids = np.full((4, 4), LOWVEG, dtype=np.uint8)
    ids[0, 0] = ROAD
    ids[0, 1] = BUILDING
    ids[1, 0] = BUILDING  # top-left 2x2 block: 2 building, 1 road, 1 low veg -> building
    ids[2:, 2:] = TREE
    ids[3, 3] = LOWVEG  # bottom-right block: 3 tree, 1 low veg -> tree
    pooled = cand.pooled_label_ids(ids, (2, 2), labels=UAVID)
    assert pooled[0, 0] == BUILDING
    assert pooled[1, 1] == TREE
    assert pooled[0, 1] == LOWVEG


def test_pool_forbidden_non_integer_scale_counts_overlapping_pixels():
    # 5 source columns onto 2 target columns: source column 2 overlaps both.
    mask = np.zeros((5, 5), dtype=bool)
    mask[:, 2] = True
    out = cand.pool_forbidden(mask, (2, 2))
    assert out.all()


def test_pooling_rejects_bad_ids():
    with pytest.raises(ValueError, match="class ids"):
        cand.pool_label_counts(np.full((4, 4), 9, dtype=np.uint8), (2, 2), labels=UAVID)


# -- valid pixels ----------------------------------------------------------------------------------
def _single_forbidden(h=60, w=60, at=(30, 30)):
    f = np.zeros((h, w), dtype=bool)
    f[at] = True
    return f


@pytest.mark.requirements("EL-R01")
def test_exact_mode_keeps_every_point_of_a_forbidden_pixel_out_of_the_disc():
    f = _single_forbidden()
    radii = np.full(60, 5.0)
    vp = cand.valid_pixels(f, radii, mode="exact")
    # a centre 6 px to the right: EDT 6, nearest point of the forbidden square at 5.5 > 5: valid
    assert vp.valid[30, 36]
    # 5 px: the square reaches 4.5 < 5: invalid (and a centre at exactly R is invalid too)
    assert not vp.valid[30, 35]
    # diagonal (4, 4): EDT 5.66, nearest corner of the square at 4.95 < 5: invalid
    assert not vp.valid[34, 34]
    # brute force: valid <=> every forbidden square is farther than R, and the disc is inside
    ys, xs = np.mgrid[0:60, 0:60]
    dx = np.maximum(np.abs(xs - 30) - 0.5, 0)
    dy = np.maximum(np.abs(ys - 30) - 0.5, 0)
    square_dist = np.hypot(dx, dy)
    border = np.minimum(np.minimum(xs + 0.5, 60 - xs - 0.5), np.minimum(ys + 0.5, 60 - ys - 0.5))
    assert not (vp.valid & ((square_dist <= 5) | (border < 5))).any()
    assert (vp.clearance[vp.valid] > 5).all()


def test_valid_pixels_respect_the_reachable_rows_and_the_border():
    f = np.zeros((50, 80), dtype=bool)
    vp = cand.valid_pixels(f, np.full(50, 4.0), min_row=10)
    assert not vp.valid[:10].any()
    assert vp.valid[10:46, 4:76].all()  # border distance 4.5 > 4
    assert not vp.valid[:, :4].any() and not vp.valid[:, 76:].any() and not vp.valid[46:].any()


def test_paper_mode_uses_squares():
    f = _single_forbidden()
    radii = np.full(60, 5.0)
    paper = cand.valid_pixels(f, radii, mode="paper")
    exact = cand.valid_pixels(f, radii, mode="exact")
    assert paper.valid[36, 36]  # Chebyshev distance 6: the square of half-width 5 stays clear
    assert not paper.valid[35, 25]  # Chebyshev 5: inside the square
    assert exact.valid[35, 25]  # Euclidean 7.07: outside the disc
    # with one constant radius, the square is stricter than the disc
    assert not (paper.valid & ~exact.valid).any()


def test_paper_radii_are_constant_per_stripe_and_top_stripes_unreachable():
    geo = CameraGeometry(width=1024, height=576)
    r = cand.row_radii(geo, SafetyParams(), "paper")
    edges = geo.stripe_edges()
    for k in range(10):
        a, b = edges[k], edges[k + 1]
        assert np.all(r[a:b] == r[a])
        assert r[a] == pytest.approx(geo.radius_px(np.array([(a + b - 1) / 2]))[0])
    exact = cand.row_radii(geo, SafetyParams(), "exact")
    assert exact[288] == pytest.approx(32.8, abs=0.05)
    with pytest.raises(ValueError, match="mode"):
        cand.row_radii(geo, SafetyParams(), "fuzzy")


# -- regions -----------------------------------------------------------------------------------------
@st.composite
def valid_masks(draw, *, max_side=36):
    """Random valid masks, dense or sparse: thin lines and isolated pixels are the hard cases."""
    h = draw(st.integers(6, max_side))
    w = draw(st.integers(6, max_side))
    return draw(hnp.arrays(dtype=bool, shape=(h, w), elements=st.booleans()))


@pytest.mark.requirements("EL-R11")
@settings(max_examples=50, deadline=None)
@given(valid_masks(), st.sampled_from([(3.0, 5), (2.0, 3), (1.5, 4), (4.0, 9)]))
def test_fast_regions_partition_core_points_like_dbscan(valid, params):
    eps, min_samples = params
    fast = reg.regions_fast(valid, eps=eps, min_samples=min_samples)
    ref = reg.regions_dbscan(valid, eps=eps, min_samples=min_samples)
    np.testing.assert_array_equal(fast.core, ref.core)
    assert fast.n_regions == ref.n_regions
    assert reg.same_partition(fast.labels[fast.core], ref.labels[ref.core])
    # noise is the same; border points join a region with a core point within eps
    np.testing.assert_array_equal(fast.labels > 0, ref.labels > 0)
    border = (fast.labels > 0) & ~fast.core
    cy, cx = np.nonzero(fast.core)
    for y, x in zip(*np.nonzero(border), strict=True):
        near = (cy - y) ** 2 + (cx - x) ** 2 <= eps * eps
        assert fast.labels[y, x] in set(fast.labels[cy[near], cx[near]])


def test_fast_regions_merge_core_points_that_are_not_8_connected():
    valid = np.zeros((20, 30), dtype=bool)
    valid[5, 2:28] = True  # a line: every point is core (7 points within 3)
    valid[8, 2:28] = True  # another line 3 px below: within eps, not 8-connected
    valid[15, 2:28] = True  # a third, 7 px below: separate
    fast = reg.regions_fast(valid)
    assert fast.n_regions == 2
    assert fast.labels[5, 10] == fast.labels[8, 20] != fast.labels[15, 10]


def test_same_partition():
    assert reg.same_partition([1, 1, 2, 3], [7, 7, 5, 9])
    assert not reg.same_partition([1, 1, 2], [7, 8, 5])
    assert not reg.same_partition([1, 2, 2], [7, 7, 7])


# -- representatives -------------------------------------------------------------------------------
@pytest.mark.requirements("EL-R01")
def test_kmeans_centroid_of_a_u_shaped_region_is_snapped_into_the_region():
    valid = np.zeros((60, 60), dtype=bool)
    valid[10:50, 10:18] = True  # left arm
    valid[10:50, 42:50] = True  # right arm
    valid[42:50, 10:50] = True  # bottom
    regions = reg.regions_fast(valid)
    assert regions.n_regions == 1
    ys, xs = np.nonzero(regions.labels == 1)
    centroid = (ys.mean(), xs.mean())
    assert not valid[int(round(centroid[0])), int(round(centroid[1]))]  # the trap: centroid outside
    rows, cols, region_of = reps.representatives(regions, n_star=1)
    assert len(rows) == 1 and region_of[0] == 1
    assert valid[rows[0], cols[0]]
    d2 = (ys - centroid[0]) ** 2 + (xs - centroid[1]) ** 2
    assert (rows[0] - centroid[0]) ** 2 + (cols[0] - centroid[1]) ** 2 == pytest.approx(d2.min())


def test_representatives_are_proportional_and_inside_their_regions():
    valid = np.zeros((80, 200), dtype=bool)
    valid[10:70, 10:150] = True  # big
    valid[10:20, 170:190] = True  # small
    regions = reg.regions_fast(valid)
    rows, cols, region_of = reps.representatives(regions, n_star=10, seed=3)
    big, small = regions.labels[40, 50], regions.labels[15, 180]
    n_big, n_small = (regions.labels == big).sum(), (regions.labels == small).sum()
    expect_big = max(1, math.floor(10 * n_big / (n_big + n_small) + 0.5))
    assert (region_of == big).sum() == expect_big
    assert (region_of == small).sum() == 1
    assert (regions.labels[rows, cols] == region_of).all()
    again = reps.representatives(regions, n_star=10, seed=3)
    for a, b in zip((rows, cols, region_of), again, strict=True):
        np.testing.assert_array_equal(a, b)


def test_kmeans_finds_separated_blobs_deterministically():
    rng = np.random.default_rng(0)
    truth = np.array([[0.0, 0.0], [50.0, 0.0], [0.0, 50.0]])
    pts = np.concatenate([c + rng.normal(size=(200, 2)) for c in truth])
    centres = reps.kmeans(pts, 3, seed=1, n_init=2)
    for c in truth:
        assert np.min(np.hypot(*(centres - c).T)) < 0.5
    np.testing.assert_array_equal(centres, reps.kmeans(pts, 3, seed=1, n_init=2))
    with pytest.raises(ValueError):
        reps.kmeans(pts, 0)


# -- overlap pruning ---------------------------------------------------------------------------------
def test_circle_overlap_area():
    assert cand.circle_overlap_area(0.0, 2.0, 3.0) == pytest.approx(math.pi * 4)
    assert cand.circle_overlap_area(5.0, 2.0, 3.0) == 0.0
    assert cand.circle_overlap_area(1.0, 1.0, 1.0) == pytest.approx(2 * math.pi / 3 - math.sqrt(3) / 2)
    # Monte Carlo check of a generic case
    rng = np.random.default_rng(0)
    p = rng.uniform(-3, 3, size=(400_000, 2))
    inside = (np.hypot(*p.T) <= 2.0) & (np.hypot(p[:, 0] - 1.7, p[:, 1]) <= 1.5)
    assert cand.circle_overlap_area(1.7, 2.0, 1.5) == pytest.approx(inside.mean() * 36, rel=0.02)


def test_prune_overlaps_walks_in_rank_order():
    rows = np.array([10.0, 10.0, 10.0, 40.0])
    cols = np.array([10.0, 11.0, 19.0, 40.0])
    radii = np.array([5.0, 5.0, 5.0, 5.0])
    kept = cand.prune_overlaps(rows, cols, radii, np.array([1, 0, 2, 3]), 0.25)
    # 1 kept first; 0 overlaps it almost wholly; 2 is 8 px from 1: overlap share ~0.07 -> kept
    assert kept.tolist() == [1, 2, 3]
    assert cand.prune_overlaps(rows, cols, radii, np.array([0, 1, 2, 3]), 1.0).tolist() == [0, 1, 2, 3]


# -- ranking -------------------------------------------------------------------------------------------
@pytest.mark.requirements("EL-R05")
def test_distance_hazard_values_and_range():
    r = np.full(5, 10.0)
    d = np.array([10.0, 20.0, 30.0, 45.0, 5.0])
    np.testing.assert_allclose(ranking.distance_hazard(d, r, 3.0), [1.0, 0.5, 0.0, 0.0, 1.0])


@pytest.mark.requirements("EL-R05")
def test_semantic_hazard_on_one_hot_maps():
    ids = np.full((40, 40), LOWVEG, dtype=np.uint8)
    ids[:, 20:] = TREE
    probs = probs_from_labels(ids, (40, 40), labels=UAVID)
    h = ranking.semantic_hazard(probs, np.array([20, 20, 20]), np.array([5, 34, 20]), np.array([3.0, 3.0, 40.0]),
                                labels=UAVID)
    assert h[0] == 0.0 and h[1] == 1.0
    assert 0.4 < h[2] < 0.6  # half tree (s=3), half low vegetation (s=0), clipped to the image
    assert ranking.combined_hazard(np.array([1.0]), np.array([0.0]), 0.5)[0] == 0.5
    order = ranking.rank_order(np.array([0.3, 0.1, 0.1]), np.array([5, 9, 2]), np.array([0, 0, 0]))
    assert order.tolist() == [2, 1, 0]


# -- configuration, input checks, default area -------------------------------------------------
@pytest.mark.parametrize(
    "kwargs,name",
    [({"mode": "fuzzy"}, "mode"), ({"n_star": 0}, "n_star"), ({"alpha": 1.5}, "alpha"),
     ({"overlap_max": -0.1}, "overlap_max"), ({"region_method": "hdbscan"}, "region_method"),
     ({"dbscan_eps": float("nan")}, "dbscan_eps"), ({"working_width": 3}, "working_width"),
     ({"d_max_factor": 1.0}, "d_max_factor"), ({"n_star": True}, "n_star")],
)
def test_config_rejects_bad_values_naming_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        CoreConfig(**kwargs)


def test_config_round_trips_through_a_dict():
    cfg = CoreConfig(mode="paper", n_star=7, pose=Pose(height_m=40.0, pitch_deg=50.0))
    d = cfg.to_dict()
    assert d["pose"] == {"height_m": 40.0, "pitch_deg": 50.0}
    assert CoreConfig.from_dict(d) == cfg
    with pytest.raises(ValueError, match="unknown"):
        CoreConfig.from_dict({"nstar": 3})


@pytest.mark.requirements("EL-R06")
@pytest.mark.parametrize("problem", ["nan", "inf", "logits", "not_normalised", "shape", "aspect", "int"])
def test_bad_probabilities_raise_instead_of_giving_candidates(problem):
    probs = probs_from_labels(np.full((72, 128), LOWVEG, dtype=np.uint8), (128, 72), labels=UAVID)
    size = (256, 144)
    if problem == "nan":
        probs[2, 30, 30] = np.nan
    elif problem == "inf":
        probs[0, 0, 0] = np.inf
    elif problem == "logits":
        probs = probs * 8 - 3
    elif problem == "not_normalised":
        probs = probs * 0.5
    elif problem == "shape":
        probs = probs[:5]
    elif problem == "aspect":
        size = (256, 256)
    elif problem == "int":
        probs = probs.astype(np.int32)
    with pytest.raises(ValueError):
        run_core(probs, size, CoreConfig(working_width=128), labels=UAVID)
    with pytest.raises(ValueError):
        check_probs(probs, size, labels=UAVID)


def test_default_area_is_tangent_to_the_bottom_edge_with_its_rows_radius():
    for W, H in [(1024, 576), (3840, 2160), (256, 144)]:
        area = default_area(W, H)
        assert area.x == W / 2
        assert area.y + area.radius_px == pytest.approx(H)
        geo = CameraGeometry(width=W, height=H)
        assert area.radius_px == pytest.approx(geo.radius_px(np.array([area.y - 0.5]))[0], rel=1e-6)
