"""Geometry for any camera and pose: the default area is the ground below the UAV and the
unreachable stripes follow from the pose, not a fixed share; the paper's 45 degree case is unchanged."""

import json
import math

import jsonschema
import numpy as np
import pytest

from el.base.decision import DEFAULT_AREA_BASES, Decision, Disc, decision_schema
from el.geometry.camera import NUM_STRIPES, REACH_M, UNREACHABLE_STRIPES, CameraGeometry, Pose, geometry_problem
from el.geometry.config import CoreConfig
from el.landing.core import default_area, reachable_working_row

W, H = 3840, 2160


def _config(pitch: float, height: float = 50.0) -> CoreConfig:
    return CoreConfig(pose=Pose(height_m=height, pitch_deg=pitch))


def _radius_at(cfg: CoreConfig, y: float) -> float:
    return float(cfg.geometry(W, H).radius_px(np.array([y - 0.5]), cfg.safety)[0])


@pytest.mark.parametrize("height", [5.0, 15.0, 30.0, 50.0])
def test_a_nadir_camera_lands_at_the_image_centre_and_reaches_every_stripe(height):
    cfg = _config(90.0, height)
    g = cfg.geometry(W, H)
    assert g.nadir_y == H / 2 and g.unreachable_stripes == 0 and g.first_reachable_row == 0
    assert g.reachable_rows().all() and geometry_problem(g) is None
    area = default_area(W, H, cfg)
    assert (area.x, area.y, area.basis) == (W / 2, H / 2, "nadir")
    assert area.radius_px == pytest.approx(min(_radius_at(cfg, H / 2), H / 2))
    assert area.basis_text == DEFAULT_AREA_BASES["nadir"]


def test_the_papers_oblique_case_keeps_the_bottom_centre_disc_and_drops_the_top_two_stripes():
    cfg = CoreConfig()
    g = cfg.geometry(W, H)
    assert g.reach_m == REACH_M and g.nadir_y > H  # the ground below is out of view
    assert g.unreachable_stripes == UNREACHABLE_STRIPES == 2 and g.first_reachable_row == 432
    reach = g.reachable_rows()
    assert not reach[:432].any() and reach[432:].all()
    # the reach lies between the ground the top rows of stripes 1 and 2 see: a round value with margin
    assert g.ground_distance(215.5) > REACH_M + 10 > REACH_M > g.ground_distance(431.5) + 5
    area = default_area(W, H, cfg)
    assert area.basis == "nearest_ground" and area.x == W / 2
    assert area.y + area.radius_px == pytest.approx(H)  # tangent to the bottom edge
    assert area.radius_px == pytest.approx(_radius_at(cfg, area.y), abs=1e-6)
    # the numbers before the geometry followed the pose, at full and at working resolution
    assert (area.y, area.radius_px) == pytest.approx((1993.0065205960693, 166.99347940393068), abs=1e-9)
    assert reachable_working_row((W, H), (1024, 576), cfg) == (115, 432)
    assert cfg.geometry(1024, 576).first_reachable_row == 115


@pytest.mark.parametrize("pitch", [75.0, 70.0, 60.0])
def test_a_nadir_point_below_the_centre_places_the_disc_at_its_row(pitch):
    cfg = _config(pitch)
    g = cfg.geometry(W, H)
    col, row = g.ground_to_pixel(np.array(0.0), np.array(0.0))  # pixel indices: + 0.5 for image coordinates
    assert float(col) + 0.5 == pytest.approx(W / 2) and float(row) + 0.5 == pytest.approx(g.nadir_y)
    assert g.first_reachable_row == 0  # 50 m up, 60-75 degrees down: all in view within reach
    area = default_area(W, H, cfg)
    assert area.x == W / 2 and area.radius_px == pytest.approx(_radius_at(cfg, area.y), abs=1e-6)
    assert area.y + area.radius_px <= H + 1e-9
    if pitch == 75.0:  # room below: centred on the nadir point
        assert area.basis == "nadir" and area.y == pytest.approx(g.nadir_y)
    elif pitch == 70.0:  # near the bottom edge: moved up just inside, still over the nadir point
        assert area.basis == "nadir" and H / 2 < area.y < g.nadir_y <= area.y + area.radius_px
        assert area.y + area.radius_px == pytest.approx(H)
    else:  # 60 degrees: the nadir point is below the image
        assert g.nadir_y > H and area.basis == "nearest_ground"
        assert area.y + area.radius_px == pytest.approx(H)


def test_stripes_follow_height_pitch_and_reach():
    def first(**kw):
        return CameraGeometry(width=W, height=H, **kw).first_reachable_row
    assert first(pose=Pose(height_m=50.0, pitch_deg=45.0), reach_m=10_000.0) == 0  # 22 degrees down at the top
    assert first(pose=Pose(height_m=50.0, pitch_deg=20.0), reach_m=10_000.0) == 432  # sky, then 1.4 degrees down
    assert first(pose=Pose(height_m=60.0, pitch_deg=45.0)) == 648  # higher: the ground in view is farther
    assert first(pose=Pose(height_m=40.0, pitch_deg=45.0)) == 216
    assert first(pose=Pose(height_m=50.0, pitch_deg=12.0)) == H - H // NUM_STRIPES  # only the bottom stripe
    assert first(pose=Pose(height_m=50.0, pitch_deg=5.0)) == H  # nothing within reach: no candidate at all
    nothing = CameraGeometry(width=W, height=H, pose=Pose(height_m=50.0, pitch_deg=5.0))
    assert not nothing.reachable_rows().any() and geometry_problem(nothing) is None
    with pytest.raises(ValueError, match="reach_m"):
        CoreConfig(reach_m=0.0)
    assert CoreConfig.from_dict(CoreConfig(reach_m=120.0).to_dict()).reach_m == 120.0


def test_a_reachable_row_still_looks_three_degrees_down():
    for pitch in np.arange(5.0, 90.1, 2.5):
        for height in (2.0, 10.0, 50.0, 300.0):
            for reach in (30.0, REACH_M, 10_000.0):
                g = CameraGeometry(width=640, height=360, pose=Pose(height_m=height, pitch_deg=float(pitch)),
                                   reach_m=reach)
                row = g.first_reachable_row
                if row < g.height:
                    assert math.degrees(float(g.depression(row - 0.5))) >= 3.0
                    assert float(g.ground_distance(row - 0.5)) <= reach
                assert geometry_problem(g) is None


def test_the_decision_records_the_basis_and_stays_valid_json():
    area = default_area(W, H, _config(90.0))
    d = Decision(action="default", reason="no_candidate", selected=None, candidates=[], default_area=area,
                 timings={"total_s": 0.1}, input={"width": W, "height": H}, config={})
    data = json.loads(d.to_json())
    assert data["default_area"]["basis"] == "nadir"
    jsonschema.validate(data, decision_schema())
    old = dict(data, default_area={"x": 1.0, "y": 2.0, "radius_px": 3.0})  # recorded before the basis
    jsonschema.validate(old, decision_schema())
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(dict(data, default_area=dict(data["default_area"], basis="elsewhere")), decision_schema())
    assert Disc(1.0, 2.0, 3.0).basis is None and Disc(1.0, 2.0, 3.0).basis_text == ""


def test_the_overlay_shades_the_stripes_of_the_decisions_own_pose():
    from assurance.campaign.gt_pipeline import decide_from_labels
    from assurance.evidence.overlay import _first_reachable_row
    from el.classes.labels import CLASS_IDS, UAVID
    from el.flight.kernel import FramePose

    ids = np.full((216, 384), CLASS_IDS["low_vegetation"], np.uint8)
    cfg = CoreConfig(working_width=192)
    nominal = decide_from_labels(ids, config=cfg, labels=UAVID)
    nadir = decide_from_labels(ids, config=cfg, pose=FramePose(Pose(height_m=60.0, pitch_deg=90.0)), labels=UAVID)
    assert _first_reachable_row(nominal.to_dict(), 384, 216) == 43
    assert _first_reachable_row(nadir.to_dict(), 384, 216) == 0
    assert (nominal.default_area.basis, nadir.default_area.basis) == ("nearest_ground", "nadir")
    assert (nadir.default_area.x, nadir.default_area.y) == (192.0, 108.0)
    assert min(c.y for c in nadir.candidates) < 43  # candidates in the former top stripes
    assert _first_reachable_row({}, 384, 216) == 43  # a decision that records no pose: the nominal one


def test_a_system_file_sets_the_reach(tmp_path):
    """``[safety] reach_m`` reaches the core: a longer reach targets the paper's far stripes too."""
    from assurance.system import default_system
    from assurance.system.find import load_system
    from assurance.system.system import System

    path = tmp_path / "uav-el.toml"
    path.write_text("[safety]\nreach_m = 200.0\n")
    far = System.build(load_system(path)).core
    shipped = System.build(default_system()).core
    assert far.reach_m == 200.0 and far.geometry(3840, 2160).first_reachable_row == 0
    assert shipped.reach_m == 90.0 and shipped.geometry(3840, 2160).first_reachable_row == 432
