"""Image perturbations for the evaluation scenarios (docs/architecture.md section 4.1).

One plain function per perturbation, all with the same signature::

    f(image, severity, rng) -> image

``image`` is an RGB ``uint8`` array of shape (H, W, 3), ``severity`` an integer in 1..5 and
``rng`` a ``numpy.random.Generator`` (the only source of randomness: a campaign seeds one per
image, so a scenario is reproducible). The result is a new ``uint8`` array of the same shape;
the input is never modified. The first line of each function is its severity table, so what
"severity 3" means can be reviewed at a glance; severity 3 reproduces the defaults of the
authors' follow-up code (jorisguerin/MLSafetyMonitors-unifiedEvaluation-experiments,
``UseCase1/Utils/perturb_utils.py`` and ``UseCase1/Params/params_perturb.py``):

============== ======================================================= ======================
name           what it does                                            severity 1..5
============== ======================================================= ======================
none           a copy of the image                                     (no effect)
brightness     V += d in HSV (V in [0, 1]), clipped                    d = .1 .3 **.5** .7 .9
fog            Hendrycks plasma-fractal fog (imagecorruptions' levels)  (c, decay) as in fog()
motion_blur    normalised vertical line kernel of k px                 k = 10 20 **30** 40 50
shifted_pixels each row cyclically shifted left by its own offset      max = 2 5 **10** 20 40
               drawn uniformly in [0, max] px
pixel_trap     n distinct random rows set to 0 (dead sensor lines)     n = 2 5 **10** 20 40
============== ======================================================= ======================

Extras beyond the paper's six: ``gaussian_noise`` (imagecorruptions' table).
Each function is registered with its traits (``TRAITS``, a ``Traits`` per name): whether it draws
random numbers, whether its severity changes it (``none``'s does not, so a campaign runs it at one
severity only: ``severities_of``) and whether it is one of the paper's six. ``PAPER_PERTURBATIONS``
names the six the paper (and requirement EL-R08) uses; ``PERTURBATIONS`` maps every name to its
function, and ``perturb`` is the one validating entry point.

Deliberate differences from the authors' code (each documented at its function): the shift
offsets include the upper bound 10 (their ``randint(0, 10)`` stops at 9; section 4.1 of the architecture says [0, 10]);
the motion-blur kernel is a true (k, 1) column, where their even-sized (30, 30) kernel with its
line in column 14 (anchor 15) also shifted the image one pixel to the right; results are
rounded, not truncated, to ``uint8``; fog follows imagecorruptions (the authors' copy pads the
image to 4096 x 4096 and divides by ``max + first row`` where imagecorruptions divides by
``max + c``, a broadcasting slip; and their params file sets ``fog_intensity = 0``, an index
into the same levels, i.e. (1.5, 2) = our severity 1, while severity 3 here is (2.5, 1.7)).

Examples
--------
>>> import numpy as np
>>> img = np.full((4, 6, 3), 100, dtype=np.uint8)
>>> out = perturb(img, "pixel_trap", 1, np.random.default_rng(0))
>>> out.shape, out.dtype, int((out.max(axis=(1, 2)) == 0).sum())
((4, 6, 3), dtype('uint8'), 2)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import cv2
import numpy as np

from el.base.rgb import check_rgb

__all__ = [
    "PAPER_PERTURBATIONS",
    "PERTURBATIONS",
    "SEVERITIES",
    "TRAITS",
    "Perturbation",
    "Traits",
    "brightness",
    "fog",
    "gaussian_noise",
    "motion_blur",
    "none",
    "perturb",
    "pixel_trap",
    "plasma_fractal",
    "severities_of",
    "shifted_pixels",
]

Perturbation = Callable[[np.ndarray, int, np.random.Generator], np.ndarray]
SEVERITIES: tuple[int, ...] = (1, 2, 3, 4, 5)

_T = TypeVar("_T")
_F = TypeVar("_F", bound=Perturbation)


@dataclass(frozen=True)
class Traits:
    """What the harness needs to know about a perturbation besides its function."""

    random: bool
    """It draws from ``rng``: its result depends on the campaign's per-image seed."""
    graded: bool = True
    """Its severity changes it (False: one severity shows everything; a campaign runs only the first)."""
    paper: bool = True
    """One of the paper's six scenarios."""


PERTURBATIONS: dict[str, Perturbation] = {}
"""Every perturbation by name (the function's own name, so names cannot drift), in definition order."""
TRAITS: dict[str, Traits] = {}
"""Every perturbation's traits by name (filled with ``PERTURBATIONS`` by ``_registered``)."""


def _registered(traits: Traits) -> Callable[[_F], _F]:
    """Register a perturbation function under its own name with its traits."""
    def wrap(func: _F) -> _F:
        PERTURBATIONS[func.__name__] = func
        TRAITS[func.__name__] = traits
        return func
    return wrap


def severities_of(name: str, severities: Sequence[_T]) -> Sequence[_T]:
    """The severities a campaign evaluates ``name`` at: all of them, or the first one when it is not graded."""
    return severities if TRAITS[name].graded else severities[:1]


def _level(table: Sequence[_T], severity: int) -> _T:
    """The entry of a 5-level severity table, rejecting anything but an integer in 1..5."""
    if isinstance(severity, bool) or not isinstance(severity, int | np.integer) or not 1 <= severity <= 5:
        raise ValueError(f"severity must be an integer in 1..5, got {severity!r}")
    return table[int(severity) - 1]


def _check_image(image: np.ndarray) -> None:
    check_rgb(image, "image")


# --------------------------------------------------------------------------------------------
# The paper's six
# --------------------------------------------------------------------------------------------


@_registered(Traits(random=False, graded=False))
def none(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """No perturbation: a copy of ``image`` (severity is validated, then ignored)."""
    _level(SEVERITIES, severity)
    _check_image(image)
    return image.copy()


@_registered(Traits(random=False))
def brightness(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Brighter scene: add ``d`` to the HSV value channel (V in [0, 1]), clipped at 1.

    Hue and saturation are kept, so every channel of a pixel scales by ``V' / V``; a black
    pixel (V = 0) becomes grey ``d``. Severity 3 is the authors' ``V += 0.5``.
    """
    d = _level((0.1, 0.3, 0.5, 0.7, 0.9), severity)
    _check_image(image)
    work = np.multiply(image, np.float32(1 / 255), dtype=np.float32)
    cv2.cvtColor(work, cv2.COLOR_RGB2HSV, dst=work)  # float HSV: H in [0, 360), S and V in [0, 1]
    v = work[..., 2]
    v += np.float32(d)
    np.minimum(v, np.float32(1), out=v)
    cv2.cvtColor(work, cv2.COLOR_HSV2RGB, dst=work)
    return cv2.convertScaleAbs(work, alpha=255.0)  # x 255, rounded and saturated to uint8


def plasma_fractal(mapsize: int, wibbledecay: float, rng: np.random.Generator) -> np.ndarray:
    """Square plasma-fractal height map (diamond-square), normalised to [0, 1].

    Hendrycks' ``plasma_fractal`` (ImageNet-C, as in imagecorruptions), including its noise
    amplitude ``wibble * U(-wibble, wibble)`` with ``wibble = 100`` divided by ``wibbledecay``
    at each level, and its wrap-around neighbours. It gives the same numbers, bit for bit,
    for the same stream of uniforms, but builds the map coarse-to-fine on contiguous grids
    instead of ``np.roll`` on strided views (about twice as fast at 4096 x 4096).

    Parameters
    ----------
    mapsize : int
        Side of the map, a power of two (>= 1).
    wibbledecay : float
        Factor (> 1) by which the noise amplitude shrinks at each finer level: lower = more
        fine detail.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray of shape (mapsize, mapsize), float64, min 0 and max 1 (all 0 when mapsize is 1).
    """
    g = _plasma_raw(mapsize, wibbledecay, rng)
    g -= g.min()
    top = g.max()
    if top > 0:
        g /= top
    return g


def _plasma_raw(mapsize: int, wibbledecay: float, rng: np.random.Generator) -> np.ndarray:
    """The plasma fractal before normalisation (float64, ``mapsize`` x ``mapsize``)."""
    if (
        isinstance(mapsize, bool)
        or not isinstance(mapsize, int | np.integer)
        or mapsize < 1
        or mapsize & (mapsize - 1)
    ):
        raise ValueError(f"mapsize must be a power of two, got {mapsize!r}")
    if not wibbledecay > 1:
        raise ValueError(f"wibbledecay must be > 1, got {wibbledecay!r}")
    wibble = 100.0

    def wibbled_mean(acc: np.ndarray) -> np.ndarray:  # acc / 4 + wibble * U(-wibble, wibble), in place
        noise = rng.uniform(-wibble, wibble, acc.shape)
        noise *= wibble
        acc *= 0.25
        acc += noise
        return acc

    g = np.zeros((1, 1))
    n = 1
    while n < mapsize:
        gp = np.empty((n + 1, n + 1))  # the n x n grid with its wrap-around row and column
        gp[:n, :n] = g
        gp[n, :n] = g[0]
        gp[:, n] = gp[:, 0]
        pairs = gp[:n, :] + gp[1:, :]  # G[i, j] + G[i+1, j], n x (n+1)
        # square centres (i+1/2, j+1/2): (G[i,j] + G[i+1,j]) + (G[i,j+1] + G[i+1,j+1])
        s = wibbled_mean(pairs[:, :n] + pairs[:, 1:])
        finer = np.empty((2 * n, 2 * n))
        finer[0::2, 0::2] = g
        finer[1::2, 1::2] = s
        # diamonds (i, j+1/2): (S[i,j] + S[i-1,j]) + (G[i,j] + G[i,j+1])
        sp = np.empty((n + 1, n))
        sp[1:] = s
        sp[0] = s[n - 1]
        finer[0::2, 1::2] = wibbled_mean((sp[1:] + sp[:-1]) + (gp[:n, :n] + gp[:n, 1:]))
        # diamonds (i+1/2, j): (S[i,j] + S[i,j-1]) + (G[i,j] + G[i+1,j])
        sp = np.empty((n, n + 1))
        sp[:, 1:] = s
        sp[:, 0] = s[:, n - 1]
        finer[1::2, 0::2] = wibbled_mean((sp[:, 1:] + sp[:, :-1]) + pairs[:, :n])
        g = finer
        n *= 2
        wibble /= wibbledecay
    return g


@_registered(Traits(random=True))
def fog(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Fog: a plasma fractal added to the image, then rescaled (imagecorruptions' ``fog``).

    ``(c, decay)`` per severity are imagecorruptions' levels: ``c`` is the fog thickness,
    ``decay`` the fractal's roughness (lower = patchier). The fractal is drawn on the smallest
    power-of-two square that covers the image (4096 for 3840 x 2160) and cropped to the
    top-left (H, W). Output ``clip((x + c F) * m / (m + c))`` with ``x`` in [0, 1] and ``m``
    the image maximum, so an all-black image stays black (as in imagecorruptions).
    """
    c, decay = _level(((1.5, 2.0), (2.0, 2.0), (2.5, 1.7), (2.5, 1.5), (3.0, 1.4)), severity)
    _check_image(image)
    h, w = image.shape[:2]
    mapsize = 1 << (max(h, w) - 1).bit_length()
    raw = _plasma_raw(mapsize, decay, rng)
    lo, span = raw.min(), np.ptp(raw)  # F = (raw - lo) / span over the whole map, then cropped
    peak = float(image.max()) / 255.0
    scale = peak / (peak + c)
    # in 0..255 units: image * scale + 255 c F scale
    gain = 255.0 * c * scale / span if span > 0 else 0.0
    haze = ((raw[:h, :w] - lo) * gain).astype(np.float32)
    return cv2.addWeighted(image, scale, cv2.merge([haze, haze, haze]), 1.0, 0.0, dtype=cv2.CV_8U)


@_registered(Traits(random=False))
def motion_blur(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Vertical motion blur: mean over a vertical line of ``k`` pixels.

    The kernel is a (k, 1) column of ``1/k`` (OpenCV box filter, anchor at row ``k // 2``,
    reflect-101 border, OpenCV's default as in the authors' ``filter2D``): columns never mix, so
    a vertical edge stays sharp and a horizontal one spreads over ``k`` rows. Severity 3 is
    the authors' 30 px.
    """
    k = _level((10, 20, 30, 40, 50), severity)
    _check_image(image)
    return cv2.blur(image, (1, k))


@_registered(Traits(random=True))
def shifted_pixels(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Row jitter (sensor read-out fault): each row shifted cyclically left by its own offset.

    Offsets are drawn independently per row, uniformly in ``[0, max_shift]`` px (both ends
    included); ``out[i, j] = image[i, (j + offset_i) mod W]``. Severity 3 is the authors' 10 px.
    """
    max_shift = _level((2, 5, 10, 20, 40), severity)
    _check_image(image)
    h, w = image.shape[:2]
    offsets = rng.integers(0, max_shift, size=h, endpoint=True)
    out = np.empty_like(image)
    for s in np.unique(offsets):  # at most max_shift + 1 groups of rows, each one vectorised
        rows = np.flatnonzero(offsets == s)
        s = int(s) % w
        out[rows, : w - s] = image[rows, s:]
        out[rows, w - s :] = image[rows, :s]
    return out


@_registered(Traits(random=True))
def pixel_trap(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Dead sensor lines: ``n`` distinct rows, drawn at random, set to 0 (black).

    All rows go black when the image has fewer than ``n``. Severity 3 is the authors' 10 rows.
    """
    n = _level((2, 5, 10, 20, 40), severity)
    _check_image(image)
    h = image.shape[0]
    out = image.copy()
    out[rng.choice(h, size=min(n, h), replace=False)] = 0
    return out


# --------------------------------------------------------------------------------------------
# Extras
# --------------------------------------------------------------------------------------------


@_registered(Traits(random=True, paper=False))
def gaussian_noise(image: np.ndarray, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Sensor noise: i.i.d. Gaussian noise of standard deviation ``sigma`` (image in [0, 1]).

    imagecorruptions' table. Not one of the paper's perturbations.
    """
    sigma = _level((0.08, 0.12, 0.18, 0.26, 0.38), severity)
    _check_image(image)
    noise = rng.standard_normal(image.shape, dtype=np.float32)
    return cv2.addWeighted(image, 1.0, noise, 255.0 * sigma, 0.0, dtype=cv2.CV_8U)


PAPER_PERTURBATIONS: tuple[str, ...] = tuple(name for name, t in TRAITS.items() if t.paper)
"""The six scenarios of the paper (requirement EL-R08), in its order apart from ``none`` first."""


def perturb(image: np.ndarray, name: str, severity: int, rng: np.random.Generator) -> np.ndarray:
    """Apply the perturbation ``name`` at ``severity`` to ``image``: the validating entry point.

    Parameters
    ----------
    image : ndarray of shape (H, W, 3), uint8
        RGB image; not modified.
    name : str
        A key of ``PERTURBATIONS``.
    severity : int
        1 (mild) .. 5 (strong); 3 reproduces the paper's settings.
    rng : numpy.random.Generator
        Source of randomness (seed it per image for reproducible scenarios).

    Returns
    -------
    ndarray of shape (H, W, 3), uint8

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones), severity outside 1..5, or an image
        that is not (H, W, 3) uint8.
    TypeError
        ``rng`` is not a ``numpy.random.Generator``.
    """
    try:
        func = PERTURBATIONS[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown perturbation {name!r}; valid names: {', '.join(sorted(PERTURBATIONS))}"
        ) from None
    _level(SEVERITIES, severity)
    _check_image(image)
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    return func(image, severity, rng)
