"""LHD (local high definition): reject a disc holding a pixel whose top class is forbidden."""

from __future__ import annotations

from collections.abc import Hashable

import numpy as np

from el.labels import CLASS_NAMES, FORBIDDEN_IDS, SAFE_IDS
from el.monitors.base import Monitor, PatchSegmenter, format_counts, validate_mask, validate_scores
from el.monitors.spec import MonitorSpec

_FORBIDDEN = np.array(FORBIDDEN_IDS)
_SAFE = np.array(SAFE_IDS)


def forbidden_pixels(scores: np.ndarray) -> np.ndarray:
    """True where the top-scoring class is forbidden (ties between a safe and a forbidden class
    count as forbidden: the conservative reading of argmax).

    Parameters
    ----------
    scores : ndarray of shape (8, ...), float

    Returns
    -------
    ndarray of shape (...), bool
    """
    return scores[_FORBIDDEN].max(axis=0) >= scores[_SAFE].max(axis=0)


def forbidden_counts(pixel_scores: np.ndarray) -> dict[str, int]:
    """Forbidden-pixel count per forbidden class among pixels, each named by its top forbidden class.

    Parameters
    ----------
    pixel_scores : ndarray of shape (8, m), float
        Scores of the ``m`` pixels to judge (the disc).
    """
    hit = forbidden_pixels(pixel_scores)
    if not hit.any():
        return {}
    top = _FORBIDDEN[np.argmax(pixel_scores[_FORBIDDEN][:, hit], axis=0)]
    ids, counts = np.unique(top, return_counts=True)
    return {CLASS_NAMES[i]: int(c) for i, c in zip(ids, counts, strict=True)}


def disc_pixels(scores: np.ndarray, disc_mask: np.ndarray) -> np.ndarray:
    """Validate scores (8, h, w) against a mask (h, w) and return the disc's scores (8, m)."""
    validate_mask(disc_mask)
    validate_scores(scores, disc_mask.shape)
    return take_disc(scores, disc_mask)


def take_disc(scores: np.ndarray, disc_mask: np.ndarray) -> np.ndarray:
    """``scores[..., disc_mask]`` for scores (..., h, w), as a C-contiguous array (..., m).

    (Boolean indexing would put the pixel axis first in memory, which makes the reductions that
    follow several times slower.)
    """
    if scores.ndim >= 3 and scores.shape[-3] > 1 and scores.strides[-3] == scores.itemsize:
        # Classes innermost in memory (a channels-last network's output, possibly a crop of it):
        # gather the disc's pixels with all their classes at once, then put the classes first.
        # Reshaping such an array would copy all of it.
        ys, xs = np.nonzero(disc_mask)
        picked = np.moveaxis(scores, -3, -1)[..., ys, xs, :]  # (..., m, 8)
        return np.ascontiguousarray(np.moveaxis(picked, -1, -2))
    flat = scores.reshape(*scores.shape[:-2], -1)
    return np.take(flat, np.flatnonzero(disc_mask), axis=-1)


EMPTY_DISC = "empty disc: no pixel to check"


class LHDMonitor(Monitor):
    """LHD: segment the HD patch; reject if any disc pixel's top class is forbidden.

    Parameters: see ``Monitor`` (``margin``, ``max_side``, ``clock``). An empty disc is rejected.

    Examples
    --------
    >>> import numpy as np
    >>> scores = np.zeros((8, 3, 3), np.float32); scores[5] = 1.0   # low vegetation everywhere
    >>> scores[2, 1, 1] = 2.0                                       # one road pixel
    >>> LHDMonitor().decide(scores, np.ones((3, 3), bool))
    (False, 'forbidden class in disc: road (1 px)')
    """

    @property
    def spec(self) -> MonitorSpec:
        return MonitorSpec()

    @property
    def feature_key(self) -> Hashable:
        return ("softmax",)

    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        return segmenter.predict_patch(rgb_patch)

    def decide(self, scores: np.ndarray, disc_mask: np.ndarray) -> tuple[bool, str]:
        return self.judge_pixels(disc_pixels(scores, disc_mask))

    def judge_pixels(self, pixel_scores: np.ndarray) -> tuple[bool, str]:
        """The rule on the disc's pixels only: scores (8, m), already validated."""
        return lhd_rule(pixel_scores)


def lhd_rule(pixel_scores: np.ndarray) -> tuple[bool, str]:
    """LHD on the disc's pixel scores (8, m): ``(accepted, reason)``."""
    m = pixel_scores.shape[1]
    if m == 0:
        return False, EMPTY_DISC
    counts = forbidden_counts(pixel_scores)
    if counts:
        return False, lhd_reason(counts)
    return True, f"no forbidden pixel in disc ({m} px)"


def lhd_reason(counts: dict[str, int]) -> str:
    noun = "class" if len(counts) == 1 else "classes"
    return f"forbidden {noun} in disc: {format_counts(counts)}"
