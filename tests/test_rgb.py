"""The one RGB check (el.base.rgb) and its callers: monitors' patches, the segmenter, the perturbations."""

from __future__ import annotations

import numpy as np
import pytest

from el.base.rgb import check_rgb


def test_accepts_rgb_uint8_and_returns_it() -> None:
    img = np.zeros((16, 20, 3), np.uint8)
    assert check_rgb(img) is img
    assert check_rgb(img, min_size=16) is img


@pytest.mark.parametrize(("image", "message"), [
    ([[0, 0, 0]], "frame must be a numpy array, got list"),
    (np.zeros((8, 8), np.uint8), r"frame must have shape \(H, W, 3\), got \(8, 8\)"),
    (np.zeros((8, 8, 4), np.uint8), r"frame must have shape \(H, W, 3\), got \(8, 8, 4\)"),
    (np.zeros((8, 8, 3), np.float32), "frame must be uint8, got float32"),
    (np.zeros((0, 8, 3), np.uint8), "frame of 8x0 px is too small"),
])
def test_rejects_with_the_first_problem_named(image: object, message: str) -> None:
    with pytest.raises(ValueError, match=f"^{message}$"):
        check_rgb(image, "frame")


def test_minimum_size_is_per_caller() -> None:
    small = np.zeros((15, 40, 3), np.uint8)
    assert check_rgb(small) is small
    with pytest.raises(ValueError, match="image of 40x15 px is too small"):
        check_rgb(small, min_size=16)


def test_callers_share_it() -> None:
    from assurance.perturbations import perturb
    from el.monitors.patches import validate_rgb
    from el.segmentation.inference import _check_rgb

    bad = np.zeros((20, 20, 3), np.float32)
    for call in (lambda: validate_rgb(bad, "hd_image"), lambda: _check_rgb(bad, "patch"),
                 lambda: perturb(bad, "none", 3, np.random.default_rng(0))):
        with pytest.raises(ValueError, match="must be uint8, got float32"):
            call()
    with pytest.raises(ValueError, match="patch of 15x15 px is too small"):  # the segmenter needs 16 px
        _check_rgb(np.zeros((15, 15, 3), np.uint8), "patch")
    assert validate_rgb(np.zeros((1, 1, 3), np.uint8)).shape == (1, 1, 3)  # a monitor's crop may be tiny


def test_the_flight_path_and_the_writers_use_it_too(tmp_path) -> None:
    from assurance.dataio.uavid import write_image
    from assurance.fitting.network.baseline import pixel_features
    from el.flight.pipeline import EmergencyLanding

    bad = np.zeros((20, 20, 3), np.float32)
    with pytest.raises(ValueError, match="^image must be uint8, got float32$"):
        EmergencyLanding._read(None, bad, {})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^image of 15x20 px is too small$"):
        EmergencyLanding._read(None, np.zeros((20, 15, 3), np.uint8), {})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="out.png: image must be uint8, got float32"):
        write_image(tmp_path / "out.png", bad)
    with pytest.raises(ValueError, match="^image must have shape"):
        pixel_features(np.zeros((20, 20), np.uint8))
