"""Properties of the CM and the ground-truth pipeline on generated label maps (EL-R01, EL-R05, EL-R11).

The maps are small (full resolution 256x144 .. 384x216, working width 128 or 192, including a
non-integer scale) with roads (thin diagonal ones too), buildings, cars, vegetation and people.
The properties are checked at FULL resolution, where the requirement holds.
"""

import json
import math

import cv2
import jsonschema
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from assurance.campaign.gt_pipeline import decide_from_labels, decision_schema
from el.base.decision import Candidate, Decision, Disc, MonitorVerdict
from el.classes.labels import CLASS_IDS, UAVID, forbidden_mask
from el.geometry.camera import CameraGeometry, working_size
from el.geometry.config import CoreConfig
from el.landing import candidates as cand
from el.landing import regions as reg
from el.landing.core import full_resolution, probs_from_labels, reachable_working_row, run_core

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
# (full width, full height, working width): scale 2, scale 2, and a non-integer scale
SIZES = [(256, 144, 128), (384, 216, 192), (300, 169, 128)]
SAFE_BACKGROUNDS = [CLASS_IDS["low_vegetation"], CLASS_IDS["clutter"], CLASS_IDS["tree"]]
CARS = [CLASS_IDS["static_car"], CLASS_IDS["moving_car"]]


# -- strategies ------------------------------------------------------------------------------------
@st.composite
def roads(draw, *, width, height):
    """A straight road between two points, 1 px (thin diagonal) to a wide avenue."""
    x0, x1 = draw(st.integers(-20, width + 20)), draw(st.integers(-20, width + 20))
    y0, y1 = draw(st.integers(-20, height + 20)), draw(st.integers(-20, height + 20))
    thickness = draw(st.integers(1, max(2, width // 20)))
    return ("road", (x0, y0, x1, y1, thickness))


@st.composite
def rectangles(draw, *, width, height, kind, min_side, max_side):
    x, y = draw(st.integers(0, width - 1)), draw(st.integers(0, height - 1))
    w, h = draw(st.integers(min_side, max_side)), draw(st.integers(min_side, max_side))
    cls = draw(st.sampled_from(CARS)) if kind == "car" else CLASS_IDS["building"]
    return (kind, (x, y, w, h, cls))


@st.composite
def patches(draw, *, width, height):
    """A safe patch: tree, low vegetation or clutter ellipse."""
    x, y = draw(st.integers(0, width - 1)), draw(st.integers(0, height - 1))
    a, b = draw(st.integers(2, width // 3)), draw(st.integers(2, height // 3))
    cls = draw(st.sampled_from(SAFE_BACKGROUNDS))
    return ("patch", (x, y, a, b, cls))


@st.composite
def humans(draw, *, width, height):
    x, y = draw(st.integers(0, width - 1)), draw(st.integers(0, height - 1))
    return ("human", (x, y, draw(st.integers(0, 2))))


@st.composite
def label_maps(draw, *, sizes=SIZES, max_objects=10):
    """(ids (H, W) uint8, working width): a background, then objects painted in order.

    Shrinks towards fewer, smaller objects on a low-vegetation background.
    """
    width, height, ww = draw(st.sampled_from(sizes))
    ids = np.full((height, width), draw(st.sampled_from(SAFE_BACKGROUNDS)), dtype=np.uint8)
    objects = draw(st.lists(st.one_of(
        patches(width=width, height=height),
        roads(width=width, height=height),
        rectangles(width=width, height=height, kind="building", min_side=4, max_side=width // 4),
        rectangles(width=width, height=height, kind="car", min_side=1, max_side=6),
        humans(width=width, height=height),
    ), max_size=max_objects))
    for kind, p in objects:
        if kind == "road":
            x0, y0, x1, y1, t = p
            cv2.line(ids, (x0, y0), (x1, y1), CLASS_IDS["road"], t)
        elif kind in ("building", "car"):
            x, y, w, h, cls = p
            ids[y : y + h, x : x + w] = cls
        elif kind == "patch":
            x, y, a, b, cls = p
            cv2.ellipse(ids, (x, y), (a, b), 0, 0, 360, cls, -1)
        elif kind == "human":
            x, y, r = p
            ids[max(y - r, 0) : y + r + 1, max(x - r, 0) : x + r + 1] = CLASS_IDS["human"]
    return ids, ww


# -- helpers -----------------------------------------------------------------------------------------
def assert_candidates_safe_at_full_resolution(ids: np.ndarray, candidates: list[Candidate],
                                              geometry: CameraGeometry | None = None) -> None:
    """EL-R01 at full resolution: no point of a forbidden pixel inside a disc, disc inside the image,
    centre in a reachable row (of ``geometry``, the camera and pose planned with; default: the nominal ones)."""
    H, W = ids.shape
    first = (geometry or CameraGeometry(width=W, height=H)).first_reachable_row
    forbidden = forbidden_mask(ids)
    for c in candidates:
        assert c.radius_px > 0
        assert c.x - c.radius_px >= -1e-9 and c.x + c.radius_px <= W + 1e-9, c
        assert c.y - c.radius_px >= -1e-9 and c.y + c.radius_px <= H + 1e-9, c
        assert math.floor(c.y) >= first, c
        x0, x1 = max(int(c.x - c.radius_px) - 1, 0), min(int(c.x + c.radius_px) + 2, W)
        y0, y1 = max(int(c.y - c.radius_px) - 1, 0), min(int(c.y + c.radius_px) + 2, H)
        fy, fx = np.nonzero(forbidden[y0:y1, x0:x1])
        if fy.size:
            dx = np.maximum(np.abs(fx + x0 + 0.5 - c.x) - 0.5, 0.0)  # centre -> nearest point of the square
            dy = np.maximum(np.abs(fy + y0 + 0.5 - c.y) - 0.5, 0.0)
            dmin = float(np.sqrt(dx * dx + dy * dy).min())
            assert dmin >= c.radius_px - 1e-6, (c, dmin)


def assert_valid_pixels_safe_at_full_resolution(ids: np.ndarray, cfg: CoreConfig) -> int:
    """EL-R01 for every potential candidate: each valid working pixel, with its disc mapped to full
    resolution, holds no point of a forbidden full-resolution pixel. Returns the number checked."""
    H, W = ids.shape
    w, h = working_size(W, H, cfg.working_width)
    probs = probs_from_labels(ids, (w, h), labels=UAVID)
    min_row, _ = reachable_working_row((W, H), (w, h), cfg)
    radii = cand.row_radii(cfg.geometry(w, h), cfg.safety, cfg.mode)
    vp = cand.valid_pixels(cand.forbidden_from_probs(probs, labels=UAVID), radii, mode=cfg.mode, min_row=min_row)
    rows, cols = np.nonzero(vp.valid)
    if rows.size == 0:
        return 0
    xs, ys, rs = full_resolution(rows, cols, radii[rows], (w, h), (W, H))  # the candidates' and look-alikes' mapping
    assert (xs - rs >= -1e-9).all() and (xs + rs <= W + 1e-9).all()
    assert (ys - rs >= -1e-9).all() and (ys + rs <= H + 1e-9).all()
    assert (np.floor(ys) >= CameraGeometry(width=W, height=H).first_reachable_row).all()
    fy, fx = np.nonzero(forbidden_mask(ids))
    if fy.size == 0:
        return rows.size
    tree = cKDTree(np.stack([fx + 0.5, fy + 0.5], axis=1))
    near = tree.query_ball_point(np.stack([xs, ys], axis=1), rs + math.sqrt(2) / 2 + 1e-6)
    for k, idx in enumerate(near):
        if idx:
            idx = np.asarray(idx)
            dx = np.maximum(np.abs(fx[idx] + 0.5 - xs[k]) - 0.5, 0.0)
            dy = np.maximum(np.abs(fy[idx] + 0.5 - ys[k]) - 0.5, 0.0)
            assert float(np.sqrt(dx * dx + dy * dy).min()) >= rs[k] - 1e-6, (rows[k], cols[k])
    return rows.size


def assert_ranked(candidates: list[Candidate], alpha: float = 0.5) -> None:
    """EL-R05: ranks 0..n-1, hazards non-decreasing, every term in [0, 1] and H = alpha H_s + (1-alpha) H_d."""
    assert [c.rank for c in candidates] == list(range(len(candidates)))
    hazards = [c.hazard for c in candidates]
    assert hazards == sorted(hazards)
    for c in candidates:
        for v in (c.hazard, c.hazard_semantic, c.hazard_distance):
            assert 0.0 <= v <= 1.0
        assert c.hazard == pytest.approx(alpha * c.hazard_semantic + (1 - alpha) * c.hazard_distance, abs=1e-12)


def without_timings(decision: Decision) -> dict:
    d = decision.to_dict()
    d.pop("timings")
    return d


# -- properties ----------------------------------------------------------------------------------------
@pytest.mark.requirements("EL-R01")
@SETTINGS
@given(label_maps())
def test_no_candidate_disc_holds_a_forbidden_full_resolution_pixel(case):
    ids, ww = case
    decision = decide_from_labels(ids, config=CoreConfig(working_width=ww), labels=UAVID)
    assert not decision.reason.startswith("fault"), decision.reason
    assert_candidates_safe_at_full_resolution(ids, decision.candidates)
    if decision.candidates:
        assert decision.action == "land" and decision.selected == 0
    else:
        assert decision.action == "default" and decision.reason == "no_candidate"


@pytest.mark.requirements("EL-R01")
@SETTINGS
@given(label_maps(), st.sampled_from(["exact", "paper"]))
def test_every_valid_pixel_is_safe_at_full_resolution(case, mode):
    ids, ww = case
    assert_valid_pixels_safe_at_full_resolution(ids, CoreConfig(working_width=ww, mode=mode))


@pytest.mark.requirements("EL-R01")
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(label_maps(), st.sampled_from(["paper", "exact"]), st.sampled_from(["fast", "dbscan"]))
def test_paper_mode_and_dbscan_regions_are_safe_too(case, mode, method):
    ids, ww = case
    decision = decide_from_labels(ids, config=CoreConfig(working_width=ww, mode=mode, region_method=method),
                                  labels=UAVID)
    assert not decision.reason.startswith("fault"), decision.reason
    assert_candidates_safe_at_full_resolution(ids, decision.candidates)
    assert_ranked(decision.candidates)


@pytest.mark.requirements("EL-R05")
@SETTINGS
@given(label_maps())
def test_candidates_are_ranked_by_increasing_hazard_in_unit_range(case):
    ids, ww = case
    decision = decide_from_labels(ids, config=CoreConfig(working_width=ww), labels=UAVID)
    assert_ranked(decision.candidates)


@pytest.mark.requirements("EL-R05")
@SETTINGS
@given(label_maps(), st.floats(0.0, 1.0), st.floats(1.5, 6.0))
def test_hazard_terms_stay_in_unit_range_for_any_alpha_and_d_max(case, alpha, d_max_factor):
    ids, ww = case
    cfg = CoreConfig(working_width=ww, alpha=alpha, d_max_factor=d_max_factor)
    decision = decide_from_labels(ids, config=cfg, labels=UAVID)
    assert_ranked(decision.candidates, alpha)


@pytest.mark.requirements("EL-R11")
@SETTINGS
@given(label_maps())
def test_fast_regions_give_dbscans_partition_of_core_points_on_real_valid_masks(case):
    ids, ww = case
    H, W = ids.shape
    cfg = CoreConfig(working_width=ww)
    w, h = working_size(W, H, ww)
    probs = probs_from_labels(ids, (w, h), labels=UAVID)
    min_row, _ = reachable_working_row((W, H), (w, h), cfg)
    radii = cand.row_radii(cfg.geometry(w, h), cfg.safety, cfg.mode)
    vp = cand.valid_pixels(cand.forbidden_from_probs(probs, labels=UAVID), radii, min_row=min_row)
    fast = reg.regions_fast(vp.valid)
    ref = reg.regions_dbscan(vp.valid)
    np.testing.assert_array_equal(fast.core, ref.core)
    assert fast.n_regions == ref.n_regions
    assert reg.same_partition(fast.labels[fast.core], ref.labels[ref.core])


@pytest.mark.requirements("EL-R11")
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(label_maps())
def test_same_input_gives_the_same_decision(case):
    ids, ww = case
    cfg = CoreConfig(working_width=ww)
    first = decide_from_labels(ids, config=cfg, input_info={"path": "x"}, labels=UAVID)
    second = decide_from_labels(ids.copy(), config=cfg, input_info={"path": "x"}, labels=UAVID)
    assert without_timings(first) == without_timings(second)
    assert json.dumps(without_timings(first)) == json.dumps(without_timings(second))


@SETTINGS
@given(label_maps())
def test_every_decision_validates_against_the_schema(case):
    ids, ww = case
    decision = decide_from_labels(ids, config=CoreConfig(working_width=ww), labels=UAVID)
    jsonschema.validate(json.loads(decision.to_json()), decision_schema())


# -- examples ------------------------------------------------------------------------------------------
@pytest.mark.requirements("EL-R01")
def test_a_thin_diagonal_road_is_never_inside_a_disc():
    ids = np.full((216, 384), CLASS_IDS["low_vegetation"], dtype=np.uint8)
    cv2.line(ids, (0, 60), (383, 215), CLASS_IDS["road"], 1)
    cv2.line(ids, (383, 50), (100, 215), CLASS_IDS["road"], 2)
    cfg = CoreConfig(working_width=192)
    decision = decide_from_labels(ids, config=cfg, labels=UAVID)
    assert decision.candidates
    assert_candidates_safe_at_full_resolution(ids, decision.candidates)
    assert assert_valid_pixels_safe_at_full_resolution(ids, cfg) > 1000


@pytest.mark.requirements("EL-R03")
def test_no_valid_pixel_gives_the_default_action():
    ids = np.full((144, 256), CLASS_IDS["road"], dtype=np.uint8)
    decision = decide_from_labels(ids, config=CoreConfig(working_width=128), labels=UAVID)
    assert decision.action == "default" and decision.reason == "no_candidate"
    assert decision.selected is None and decision.candidates == []
    area = decision.default_area
    assert area.x == 128 and area.y + area.radius_px == pytest.approx(144)


@pytest.mark.requirements("EL-R06")
def test_a_fault_inside_the_cm_gives_the_default_action_with_its_reason(monkeypatch):
    import assurance.campaign.gt_pipeline as gt

    def broken(*args, **kwargs):
        raise RuntimeError("injected")

    import el.flight.kernel

    monkeypatch.setattr(el.flight.kernel, "run_core", broken)
    ids = np.full((144, 256), CLASS_IDS["low_vegetation"], dtype=np.uint8)
    decision = gt.decide_from_labels(ids, config=CoreConfig(working_width=128), labels=UAVID)
    assert decision.action == "default" and decision.reason == "fault: candidates: RuntimeError: injected"
    jsonschema.validate(decision.to_dict(), decision_schema())


def test_run_core_reports_stage_timings_and_full_resolution_geometry():
    ids = np.full((144, 256), CLASS_IDS["low_vegetation"], dtype=np.uint8)
    ids[60:70, 100:140] = CLASS_IDS["building"]
    probs = probs_from_labels(ids, (128, 72), labels=UAVID)
    result = run_core(probs, (256, 144), CoreConfig(working_width=128), labels=UAVID)
    assert set(result.timings) == {"valid_s", "regions_s", "representatives_s", "ranking_s", "total_s"}
    assert result.input_size == (256, 144) and result.working_size == (128, 72)
    assert result.candidates and result.stats["candidates"] == len(result.candidates)
    for c in result.candidates:  # centres of working pixels, scaled by 2, each of its row's radius
        assert (c.x / 2 - 0.5) == pytest.approx(round(c.x / 2 - 0.5))
        assert c.radius_px == pytest.approx(2 * result.radii[int(c.y / 2)])
    assert result.radii.shape == (72,) and np.isfinite(result.radii).all() and (result.radii > 0).all()


def test_schema_accepts_monitored_decisions_and_rejects_broken_ones():
    schema = decision_schema()
    verdict = MonitorVerdict(name="lhd+ch:tau=0.25", accepted=False, reason="unsafe pixels", seconds=0.04)
    cands = [Candidate(0, 100.0, 80.0, 12.5, 0.2, 0.3, 0.1, verdict),
             Candidate(1, 50.0, 90.0, 12.5, 0.3, 0.3, 0.3, MonitorVerdict("lhd", True, "ok", 0.01))]
    d = Decision(action="land", reason="accepted", selected=1, candidates=cands,
                 default_area=Disc(128.0, 130.0, 14.0), timings={"total_s": 0.5},
                 input={"path": "a.png", "sha256": "0" * 64, "width": 256, "height": 144}, config={})
    jsonschema.validate(d.to_dict(), schema)
    for key, value in [("action", "fly"), ("reason", "because"), ("selected", -1), ("candidates", "none")]:
        bad = d.to_dict()
        bad[key] = value
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)
    bad = d.to_dict()
    bad["candidates"][0]["hazard"] = 1.5
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
    bad = d.to_dict()
    bad["action"], bad["selected"] = "default", 0
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
