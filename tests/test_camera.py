"""Camera geometry against the reference rows of docs/architecture.md section 2.2, and the beta figure."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from el.geometry.camera import CameraGeometry, Intrinsics, Pose, SafetyParams, required_beta, working_size

REFERENCE = [  # row, dep (deg), across, along, delta, R_px
    (0, 22.2, 0.1789, 0.4372, 0.1789, 19.0),
    (115, 30.8, 0.1386, 0.2623, 0.1386, 24.5),
    (288, 45.0, 0.1035, 0.1463, 0.1035, 32.8),
    (575, 67.8, 0.0729, 0.0725, 0.0725, 46.9),
]


@pytest.mark.parametrize("row,dep,across,along,delta,r_px", REFERENCE)
def test_reference_table(row, dep, across, along, delta, r_px):
    g = CameraGeometry(width=1024, height=576)
    a, b, d = g.pixel_size(np.array([row]))
    assert np.degrees(g.depression(row)) == pytest.approx(dep, abs=0.05)
    assert a[0] == pytest.approx(across, abs=5e-5)
    assert b[0] == pytest.approx(along, abs=5e-5)
    assert d[0] == pytest.approx(delta, abs=5e-5)
    assert g.radius_px(np.array([row]))[0] == pytest.approx(r_px, abs=0.05)


def test_working_size_keeps_aspect():
    assert working_size(3840, 2160) == (1024, 576)
    assert working_size(4096, 2160) == (1024, 540)


def test_top_two_stripes_unreachable():
    g = CameraGeometry(width=1024, height=576)
    assert g.first_reachable_row == 115
    reach = g.reachable_rows()
    assert not reach[:115].any() and reach[115:].all()


def test_required_beta_for_20_percent_box():
    g = CameraGeometry(width=1024, height=576)
    beta = required_beta(g, height_error=0.2, pitch_error=0.2)
    assert beta == pytest.approx(1.56, abs=0.01)
    assert beta < SafetyParams().beta
    assert required_beta(g, height_error=0.0, pitch_error=0.0) == pytest.approx(1.0)


@settings(max_examples=50, deadline=None)
@given(
    col=st.floats(0, 3839), row=st.floats(0, 2159),
    height=st.floats(20, 100), pitch=st.floats(30, 80),
)
def test_pixel_ground_round_trip(col, row, height, pitch):
    g = CameraGeometry(width=3840, height=2160, pose=Pose(height_m=height, pitch_deg=pitch))
    x, y = g.pixel_to_ground(np.array([col]), np.array([row]))
    assert np.isfinite(x).all() and np.isfinite(y).all()
    c2, r2 = g.ground_to_pixel(x, y)
    assert c2[0] == pytest.approx(col, abs=1e-6)
    assert r2[0] == pytest.approx(row, abs=1e-6)


def test_centre_ray_hits_ground_at_h_over_tan_theta():
    g = CameraGeometry(width=1024, height=576)
    x, y = g.pixel_to_ground(np.array([511.5]), np.array([287.5]))
    assert x[0] == pytest.approx(0.0, abs=1e-9)
    assert y[0] == pytest.approx(50.0, rel=1e-9)


def test_bad_parameters_name_themselves():
    with pytest.raises(ValueError, match="height_m"):
        Pose(height_m=-5)
    with pytest.raises(ValueError, match="focal_mm"):
        Intrinsics(focal_mm=0)
    with pytest.raises(ValueError, match="beta"):
        SafetyParams(beta=0.5)
