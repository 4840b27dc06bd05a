"""LHD (local high definition): reject a disc holding a pixel whose top class is forbidden."""

from __future__ import annotations

import math
from collections.abc import Hashable
from typing import Any, ClassVar

import numpy as np

from el.classes.labels import LabelSet
from el.landing.forbidden import argmax_slack, forbidden_pixels
from el.monitors.base import (
    CandidateContext,
    Judgement,
    PatchMonitor,
    PatchSegmenter,
    format_counts,
    validate_mask,
    validate_scores,
)
from el.monitors.patches import Patch
from el.monitors.spec import MonitorSpec


def forbidden_counts(pixel_scores: np.ndarray, labels: LabelSet) -> dict[str, int]:
    """Forbidden-pixel count per forbidden class among pixels, each named by its top forbidden class.

    Parameters
    ----------
    pixel_scores : ndarray of shape (C, m), float
        Scores of the ``m`` pixels to judge (the disc), over the classes of ``labels``.
    """
    hit = forbidden_pixels(pixel_scores, labels)
    if not hit.any():
        return {}
    forbidden = np.array(labels.forbidden_ids)
    top = forbidden[np.argmax(pixel_scores[forbidden][:, hit], axis=0)]
    ids, counts = np.unique(top, return_counts=True)
    return {labels.names[i]: int(c) for i, c in zip(ids, counts, strict=True)}


def disc_pixels(scores: np.ndarray, disc_mask: np.ndarray, labels: LabelSet) -> np.ndarray:
    """Validate scores (C, h, w) against a mask (h, w) and return the disc's scores (C, m); C from ``labels``."""
    validate_mask(disc_mask)
    validate_scores(scores, disc_mask.shape, labels=labels)
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


def fraction_score(rejected: np.ndarray, slack: np.ndarray) -> float:
    """The score of the paper's pixel rules on a disc of ``m`` pixels: higher = more likely unsafe.

    ``rejected``: (m,) bool, the pixels the rule rejects; ``slack``: (m,) float, how far an accepted
    pixel is from being rejected (< 0 for every accepted pixel).

    - some pixel rejected: the fraction of rejected pixels, in (0, 1];
    - none: the largest slack, < 0 (the pixel closest to being rejected);
    - an empty disc: ``+inf``.

    So the score is > 0 exactly when the rule rejects the disc, and the paper's verdicts are those
    at threshold 0 (reject iff score > 0). A threshold of 0.01 tolerates forbidden pixels on up to
    1% of the disc; a negative one demands a margin on every pixel.
    """
    m = rejected.shape[0]
    if m == 0:
        return math.inf
    k = int(np.count_nonzero(rejected))
    if k:
        return k / m
    return float(slack.max())


class LHDMonitor(PatchMonitor):
    """LHD: segment the HD patch; reject if any disc pixel's top class is forbidden.

    Score: :func:`fraction_score` (fraction of forbidden pixels, or the best safe margin when
    there is none); threshold 0 is the paper's rule. Parameters: see ``Monitor`` (``margin``,
    ``max_side``, ``clock``, ``threshold``), and ``labels`` (keyword, required): the label set of the
    segmenter's scores, which says which classes are forbidden. An empty disc is rejected.

    Examples
    --------
    >>> import numpy as np
    >>> from el.classes.labels import UAVID
    >>> scores = np.zeros((8, 3, 3), np.float32); scores[5] = 1.0   # low vegetation everywhere
    >>> scores[2, 1, 1] = 2.0                                       # one road pixel
    >>> LHDMonitor(labels=UAVID).decide(scores, np.ones((3, 3), bool))
    (False, 'forbidden class in disc: road (1 px)')
    >>> round(LHDMonitor(labels=UAVID).score(scores, np.ones((3, 3), bool)), 4)     # 1 pixel of 9
    0.1111
    """

    SCORE_RANGE: ClassVar[tuple[float, float]] = (-1.0, 1.0)  # fraction_score: a safe margin >= -1, a fraction <= 1
    #: The label set of the scores (set by ``__init__``: a subclass calls it).
    labels: LabelSet

    def __init__(self, *, labels: LabelSet, **kwargs: Any) -> None:
        if not isinstance(labels, LabelSet):
            raise ValueError(f"labels must be a LabelSet, got {type(labels).__name__}")
        self.labels = labels
        super().__init__(**kwargs)

    @property
    def spec(self) -> MonitorSpec:
        return MonitorSpec(threshold=self.threshold)

    @property
    def feature_key(self) -> Hashable:
        return ("softmax",)

    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        return segmenter.predict_patch(rgb_patch)

    def patch_features(self, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0, size: int | None = None,
                       trunk: Any = None, context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        if trunk is None:
            return segmenter.predict_patch(patch.rgb), patch.disc_mask
        return segmenter.predict_patch(patch.rgb, features=trunk), patch.disc_mask  # type: ignore[call-arg]

    @property
    def reduce_key(self) -> Hashable:
        return ("disc_pixels", self.feature_key)

    def reduce(self, features: Any, disc_mask: np.ndarray) -> np.ndarray:
        """The disc's pixel scores (C, m), validated: shared by LHD, CH and the softmax-family monitors."""
        return disc_pixels(features, disc_mask, self.labels)

    def judge(self, reduced: Any) -> Judgement:
        return self.judge_pixels(reduced)

    def rule(self, pixel_scores: np.ndarray) -> tuple[bool, str]:
        """The paper's rule on the disc's pixels: ``(accepted, reason)``."""
        return lhd_rule(pixel_scores, self.labels)

    def rejected_pixels(self, pixel_scores: np.ndarray) -> np.ndarray:
        """(m,) bool: the disc pixels the rule rejects."""
        return forbidden_pixels(pixel_scores, self.labels)

    def judge_pixels(self, pixel_scores: np.ndarray, threshold: float | None = None) -> Judgement:
        """Score, verdict and reason on the disc's pixels only: scores (8, m), already validated.

        ``threshold``: None for this monitor's own (MCD passes its threshold to the rule it wraps).
        """
        accepted_by_rule, reason = self.rule(pixel_scores)
        if pixel_scores.shape[1] == 0:
            return Judgement(math.inf, False, reason)
        score = fraction_score(self.rejected_pixels(pixel_scores), argmax_slack(pixel_scores, self.labels))
        t = self.threshold if threshold is None else threshold
        accepted = not score > t
        if accepted != accepted_by_rule:
            reason = f"{reason}; score {score:.6g} {'<=' if accepted else '>'} threshold {t:.6g}"
        return Judgement(score, accepted, reason)


def lhd_rule(pixel_scores: np.ndarray, labels: LabelSet) -> tuple[bool, str]:
    """LHD on the disc's pixel scores (C, m) of ``labels``: ``(accepted, reason)``."""
    m = pixel_scores.shape[1]
    if m == 0:
        return False, EMPTY_DISC
    counts = forbidden_counts(pixel_scores, labels)
    if counts:
        return False, lhd_reason(counts)
    return True, f"no forbidden pixel in disc ({m} px)"


def lhd_reason(counts: dict[str, int]) -> str:
    noun = "class" if len(counts) == 1 else "classes"
    return f"forbidden {noun} in disc: {format_counts(counts)}"
