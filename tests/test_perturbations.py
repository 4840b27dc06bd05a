"""Perturbations (docs/architecture.md section 4.1): severity 3 reproduces the paper's settings, contracts hold."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from assurance.perturbations import (
    PAPER_PERTURBATIONS,
    PERTURBATIONS,
    TRAITS,
    brightness,
    fog,
    motion_blur,
    none,
    perturb,
    pixel_trap,
    plasma_fractal,
    severities_of,
    shifted_pixels,
)

SIX = ("none", "brightness", "fog", "motion_blur", "shifted_pixels", "pixel_trap")


def _texture(h: int, w: int, seed: int = 0, lo: int = 20, hi: int = 235) -> np.ndarray:
    """A smooth random RGB texture with values in [lo, hi] (no black row)."""
    rng = np.random.default_rng(seed)
    coarse = rng.integers(lo, hi + 1, size=(max(2, h // 8), max(2, w // 8), 3), dtype=np.uint8)
    return np.clip(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC), lo, hi).astype(np.uint8)


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return _texture(96, 128)


def _hendrycks_plasma(mapsize: int, wibbledecay: float, rng: np.random.Generator) -> np.ndarray:
    """Hendrycks' ImageNet-C plasma_fractal (np.roll on strided views), fed by ``rng``."""
    maparray = np.empty((mapsize, mapsize), dtype=np.float64)
    maparray[0, 0] = 0
    stepsize = mapsize
    wibble = 100.0

    def wibbledmean(array):
        return array / 4 + wibble * rng.uniform(-wibble, wibble, array.shape)

    while stepsize >= 2:
        cornerref = maparray[0:mapsize:stepsize, 0:mapsize:stepsize]
        squareaccum = cornerref + np.roll(cornerref, shift=-1, axis=0)
        squareaccum += np.roll(squareaccum, shift=-1, axis=1)
        maparray[stepsize // 2 : mapsize : stepsize, stepsize // 2 : mapsize : stepsize] = wibbledmean(
            squareaccum
        )
        drgrid = maparray[stepsize // 2 : mapsize : stepsize, stepsize // 2 : mapsize : stepsize]
        ulgrid = maparray[0:mapsize:stepsize, 0:mapsize:stepsize]
        ltsum = (drgrid + np.roll(drgrid, 1, axis=0)) + (ulgrid + np.roll(ulgrid, -1, axis=1))
        maparray[0:mapsize:stepsize, stepsize // 2 : mapsize : stepsize] = wibbledmean(ltsum)
        ttsum = (drgrid + np.roll(drgrid, 1, axis=1)) + (ulgrid + np.roll(ulgrid, -1, axis=0))
        maparray[stepsize // 2 : mapsize : stepsize, 0:mapsize:stepsize] = wibbledmean(ttsum)
        stepsize //= 2
        wibble /= wibbledecay
    maparray -= maparray.min()
    return maparray / maparray.max()


# ---------------------------------------------------------------------------------------------
# Registry and contracts
# ---------------------------------------------------------------------------------------------


def test_registry_names_are_the_function_names():
    assert set(SIX) <= set(PERTURBATIONS)
    assert PAPER_PERTURBATIONS == SIX
    for name, func in PERTURBATIONS.items():
        assert func.__name__ == name


@pytest.mark.parametrize("name", sorted(PERTURBATIONS))
@pytest.mark.parametrize("severity", [1, 3, 5])
def test_shape_dtype_kept_input_untouched_deterministic(image, name, severity):
    before = image.copy()
    a = perturb(image, name, severity, np.random.default_rng(7))
    b = perturb(image, name, severity, np.random.default_rng(7))
    assert a.shape == image.shape and a.dtype == np.uint8
    assert np.array_equal(a, b)
    assert np.array_equal(image, before)
    assert a is not image


@pytest.mark.parametrize("name", ["fog", "shifted_pixels", "pixel_trap", "gaussian_noise"])
def test_random_perturbations_depend_on_the_seed(image, name):
    a = perturb(image, name, 3, np.random.default_rng(1))
    b = perturb(image, name, 3, np.random.default_rng(2))
    assert not np.array_equal(a, b)


def test_global_numpy_random_state_untouched(image):
    np.random.seed(123)
    state = np.random.get_state()
    for name in PERTURBATIONS:
        perturb(image, name, 3, np.random.default_rng(0))
    after = np.random.get_state()
    assert state[0] == after[0] and np.array_equal(state[1], after[1]) and state[2:] == after[2:]


@settings(max_examples=40, deadline=None)
@given(
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    name=st.sampled_from(sorted(PERTURBATIONS)),
    severity=st.integers(1, 5),
    seed=st.integers(0, 2**32 - 1),
)
def test_any_image_size(h, w, name, severity, seed):
    img = np.random.default_rng(seed).integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    out = perturb(img, name, severity, np.random.default_rng(seed))
    assert out.shape == (h, w, 3) and out.dtype == np.uint8


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("severity", [0, 6, -1, 2.5, True, "3", None])
@pytest.mark.parametrize("name", sorted(PERTURBATIONS))
def test_bad_severity_rejected_by_entry_point_and_function(image, name, severity):
    with pytest.raises(ValueError, match="severity"):
        perturb(image, name, severity, np.random.default_rng(0))
    with pytest.raises(ValueError, match="severity"):
        PERTURBATIONS[name](image, severity, np.random.default_rng(0))


def test_numpy_integer_severity_accepted(image):
    out = perturb(image, "pixel_trap", np.int64(3), np.random.default_rng(0))
    assert out.shape == image.shape


def test_unknown_name_lists_valid_ones(image):
    with pytest.raises(ValueError, match="unknown perturbation 'snow'") as err:
        perturb(image, "snow", 3, np.random.default_rng(0))
    for name in SIX:
        assert name in str(err.value)
    with pytest.raises(ValueError, match="unknown perturbation"):
        perturb(image, None, 3, np.random.default_rng(0))


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((8, 8, 3), dtype=np.float32),
        np.zeros((8, 8), dtype=np.uint8),
        np.zeros((8, 8, 4), dtype=np.uint8),
        np.zeros((0, 8, 3), dtype=np.uint8),
        [[[0, 0, 0]]],
    ],
    ids=["float32", "gray", "rgba", "empty", "list"],
)
@pytest.mark.parametrize("name", sorted(PERTURBATIONS))
def test_bad_image_rejected(bad, name):
    with pytest.raises(ValueError, match="image"):
        perturb(bad, name, 3, np.random.default_rng(0))
    with pytest.raises(ValueError, match="image"):
        PERTURBATIONS[name](bad, 3, np.random.default_rng(0))


def test_rng_must_be_a_generator(image):
    with pytest.raises(TypeError, match="Generator"):
        perturb(image, "fog", 3, 42)


# ---------------------------------------------------------------------------------------------
# Severity 3 = the paper's settings (EL-R08: each of the six perturbations exists and works)
# ---------------------------------------------------------------------------------------------


@pytest.mark.requirements("EL-R08")
def test_none_is_a_copy(image):
    out = none(image, 3, np.random.default_rng(0))
    assert np.array_equal(out, image) and out is not image and not np.shares_memory(out, image)


@pytest.mark.requirements("EL-R08")
def test_brightness_raises_v_by_half(image):
    img = image.copy()
    img[0, :4] = 0  # black pixels: V = 0 -> grey 0.5
    img[1, 0] = (255, 0, 0)  # saturated already: unchanged
    out = brightness(img, 3, np.random.default_rng(0)).astype(np.float64)
    v_in = img.max(axis=2) / 255.0
    v_out = out.max(axis=2) / 255.0
    assert np.abs(v_out - np.minimum(v_in + 0.5, 1.0)).max() <= 0.51 / 255
    assert np.array_equal(out[0, :4], np.full((4, 3), 128.0))
    assert np.array_equal(out[1, 0], [255.0, 0.0, 0.0])
    # hue and saturation kept: each channel scales by V'/V
    lit = v_in > 0
    expected = img.astype(np.float64) * (np.minimum(v_in + 0.5, 1.0) / np.where(lit, v_in, 1.0))[..., None]
    assert np.abs(out[lit] - expected[lit]).max() <= 0.51


@pytest.mark.requirements("EL-R08")
def test_fog_is_imagecorruptions_fog_at_level_three():
    img = _texture(72, 100, seed=3)  # mapsize 128 (the smallest power of two >= 100), cropped to 72 x 100
    out = fog(img, 3, np.random.default_rng(11)).astype(np.float64)
    c, decay = 2.5, 1.7
    x = img / 255.0
    max_val = x.max()
    x = x + c * _hendrycks_plasma(128, decay, np.random.default_rng(11))[:72, :100][..., None]
    expected = np.clip(x * max_val / (max_val + c), 0, 1) * 255
    assert np.abs(out - expected).max() <= 0.51
    assert out.std() < img.std()  # fog lowers contrast


def test_plasma_fractal_matches_hendrycks_bit_for_bit():
    for mapsize, decay in [(1, 2.0), (2, 2.0), (16, 1.4), (256, 1.7)]:
        ours = plasma_fractal(mapsize, decay, np.random.default_rng(5))
        if mapsize == 1:
            assert np.array_equal(ours, np.zeros((1, 1)))
            continue
        ref = _hendrycks_plasma(mapsize, decay, np.random.default_rng(5))
        assert np.array_equal(ours, ref)
        assert ours.min() == 0.0 and ours.max() == 1.0


@pytest.mark.parametrize("mapsize", [0, 3, 100, 2.0, True])
def test_plasma_fractal_needs_power_of_two(mapsize):
    with pytest.raises(ValueError, match="power of two"):
        plasma_fractal(mapsize, 2.0, np.random.default_rng(0))


def _impulse_support(out: np.ndarray) -> tuple[int, int]:
    rows, cols = np.nonzero(out[..., 0])
    return int(rows.max() - rows.min() + 1), int(cols.max() - cols.min() + 1)


@pytest.mark.requirements("EL-R08")
def test_motion_blur_is_a_vertical_30px_line():
    img = np.zeros((101, 41, 3), dtype=np.uint8)
    img[50, 20] = 240
    out = motion_blur(img, 3, np.random.default_rng(0))
    assert _impulse_support(out) == (30, 1)  # 30 px tall, one column wide: vertical
    assert set(out[:, 20, 0].tolist()) == {0, 8}  # normalised kernel: 240 / 30 on each of the 30 rows

    vertical_edge = np.zeros((60, 40, 3), dtype=np.uint8)
    vertical_edge[:, 20:] = 200
    assert np.array_equal(motion_blur(vertical_edge, 3, np.random.default_rng(0)), vertical_edge)

    horizontal_edge = np.zeros((100, 40, 3), dtype=np.uint8)
    horizontal_edge[50:] = 200
    column = motion_blur(horizontal_edge, 3, np.random.default_rng(0))[:, 10, 0]
    assert np.count_nonzero((column > 0) & (column < 200)) == 29  # the edge spreads over 30 rows
    assert np.all(np.diff(column.astype(int)) >= 0)


@pytest.mark.parametrize("severity,length", [(1, 10), (2, 20), (3, 30), (4, 40), (5, 50)])
def test_motion_blur_lengths(severity, length):
    img = np.zeros((121, 9, 3), dtype=np.uint8)
    img[60, 4] = 255
    assert _impulse_support(motion_blur(img, severity, np.random.default_rng(0))) == (length, 1)


def _row_shifts(img: np.ndarray, out: np.ndarray, max_shift: int) -> np.ndarray:
    """The left cyclic shift of each row of ``out`` relative to ``img`` (-1 if none fits)."""
    shifts = np.full(img.shape[0], -1)
    for i in range(img.shape[0]):
        for s in range(max_shift + 1):
            if np.array_equal(out[i], np.roll(img[i], -s, axis=0)):
                shifts[i] = s
                break
    return shifts


@pytest.mark.requirements("EL-R08")
def test_shifted_pixels_rows_are_cyclic_shifts_within_ten():
    img = np.random.default_rng(0).integers(0, 256, size=(400, 64, 3), dtype=np.uint8)  # rows unique
    out = shifted_pixels(img, 3, np.random.default_rng(3))
    shifts = _row_shifts(img, out, 10)
    assert (shifts >= 0).all()  # every row is a cyclic shift by an offset in [0, 10]
    assert set(shifts.tolist()) == set(range(11))  # both ends reached, each row its own draw


@pytest.mark.parametrize("severity,max_shift", [(1, 2), (2, 5), (4, 20), (5, 40)])
def test_shifted_pixels_ranges(severity, max_shift):
    img = np.random.default_rng(1).integers(0, 256, size=(300, 64, 3), dtype=np.uint8)
    shifts = _row_shifts(img, shifted_pixels(img, severity, np.random.default_rng(4)), max_shift)
    assert (shifts >= 0).all() and shifts.max() == max_shift


def test_shifted_pixels_wider_than_image():
    img = np.random.default_rng(2).integers(0, 256, size=(50, 3, 3), dtype=np.uint8)
    out = shifted_pixels(img, 5, np.random.default_rng(0))  # offsets up to 40 on a 3-px row
    assert (_row_shifts(img, out, 2) >= 0).all()


@pytest.mark.requirements("EL-R08")
def test_pixel_trap_zeroes_exactly_ten_rows(image):
    out = pixel_trap(image, 3, np.random.default_rng(0))
    black = np.flatnonzero(out.max(axis=(1, 2)) == 0)
    assert black.size == 10
    keep = np.setdiff1d(np.arange(image.shape[0]), black)
    assert np.array_equal(out[keep], image[keep])


@pytest.mark.parametrize("severity,rows", [(1, 2), (2, 5), (4, 20), (5, 40)])
def test_pixel_trap_counts(image, severity, rows):
    out = pixel_trap(image, severity, np.random.default_rng(0))
    assert np.count_nonzero(out.max(axis=(1, 2)) == 0) == rows


def test_pixel_trap_small_image_all_black():
    img = np.full((3, 5, 3), 9, dtype=np.uint8)
    assert not pixel_trap(img, 3, np.random.default_rng(0)).any()


# ---------------------------------------------------------------------------------------------
# Severity scale
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(set(PERTURBATIONS) - {"none"}))
def test_higher_severity_changes_more(name):
    img = _texture(96, 128, seed=1)
    mad = np.array(
        [
            [
                np.abs(perturb(img, name, s, np.random.default_rng(seed)).astype(np.float64) - img).mean()
                for s in range(1, 6)
            ]
            for seed in range(8)
        ]
    ).mean(axis=0)
    if name == "fog":
        # imagecorruptions' levels 3 and 4 share the thickness c = 2.5 (4 is only patchier): there
        # the change may stay level; every other step thickens the fog
        assert mad[0] < mad[1] < mad[2] and mad[3] < mad[4] and mad[3] >= 0.98 * mad[2]
    else:
        assert np.all(np.diff(mad) > 0), mad


@pytest.mark.parametrize("name", sorted(PERTURBATIONS))
def test_traits_say_truly_whether_a_perturbation_draws_random_numbers_or_is_graded(name):
    image = np.random.default_rng(7).integers(0, 256, (64, 48, 3), dtype=np.uint8)
    a = PERTURBATIONS[name](image, 3, np.random.default_rng(1))
    b = PERTURBATIONS[name](image, 3, np.random.default_rng(2))
    assert (not np.array_equal(a, b)) == TRAITS[name].random
    graded = not np.array_equal(PERTURBATIONS[name](image, 1, np.random.default_rng(1)), a)
    assert graded == TRAITS[name].graded
    assert severities_of(name, (1, 3, 5)) == ((1, 3, 5) if graded else (1,))
