"""MCD (Monte-Carlo dropout, on top of LHD or LHD+CH): judge the disc on ``S = mu + 3 sigma``.

The HD patch runs ``n`` times with dropout active (keep probability rho), as one batch; per pixel
and class, ``mu`` and ``sigma`` are the empirical mean and standard deviation (``ddof=0``, as
``numpy.std``) of the softmax samples. ``S`` replaces the softmax in the wrapped rule: argmax for
LHD+MCD, the tau rule for LHD+CH+MCD.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from el.monitors.base import (
    CandidateContext,
    Judgement,
    PatchMonitor,
    PatchSegmenter,
    validate_mask,
    validate_samples,
)
from el.monitors.lhd import LHDMonitor, take_disc
from el.monitors.mc_chunks import Between, Chunking, mc_samples
from el.monitors.patches import Patch, accepts_keyword, disc_box
from el.monitors.spec import MonitorSpec, validate_n, validate_rho

MCD_SIGMAS = 3.0


def mcd_score(samples: np.ndarray, k: float = MCD_SIGMAS) -> np.ndarray:
    """``S = mu + k sigma`` over the sample axis.

    Parameters
    ----------
    samples : ndarray of shape (n, 8, ...), float
        Softmax samples with dropout active.
    k : float, default 3.0

    Returns
    -------
    ndarray of shape (8, ...), same float dtype
    """
    n = samples.shape[0]
    if n < 1:
        raise ValueError("mcd_score needs at least one sample")
    # Two passes over the samples, one (8, ...) slice at a time: the same numbers as
    # ``mean(0) + k * std(0)`` at a fraction of numpy's time and memory for a reduction on axis 0.
    mu = np.array(samples[0], copy=True)
    for i in range(1, n):
        mu += samples[i]
    mu /= n
    var = np.zeros_like(mu)
    d = np.empty_like(mu)
    for i in range(n):
        np.subtract(samples[i], mu, out=d)
        d *= d
        var += d
    var /= n
    return mu + k * np.sqrt(var)


class MCDMonitor(PatchMonitor):
    """Wraps an LHD or LHD+CH monitor and feeds it the MCD score instead of the softmax.

    Parameters
    ----------
    rule : LHDMonitor or CHMonitor
        The rule applied to ``S``; its ``margin``, ``max_side``, ``clock``, ``threshold`` and ``labels`` are used.
    n : int
        MC-dropout samples (keyword-only).
    rho : float
        Dropout keep probability (keyword-only).

    ``features`` asks the segmenter for ``n`` samples in one batch, seeded with ``seed``.
    ``check_scores``/``decide`` take samples (n', 8, h, w) with ``n' >= n`` and use the first
    ``n``: a campaign draws 30 samples once and serves the n = 10 configurations their prefix
    (equal to a 10-sample draw with the same seed, by the ``PatchSegmenter`` contract). The score
    is the wrapped rule's (``el.monitors.lhd.fraction_score``) on ``S``.
    """

    #: fraction_score of S = mean + k std (each in [0, 1 + k / 2]): a safe margin >= -(1 + k / 2), a fraction <= 1
    SCORE_RANGE: ClassVar[tuple[float, float]] = (-(1.0 + MCD_SIGMAS / 2.0), 1.0)

    def __init__(self, rule: LHDMonitor, *, n: int, rho: float, threshold: float | None = None):
        if not isinstance(rule, LHDMonitor):
            raise ValueError(f"MCD wraps an LHD or LHD+CH monitor, got {type(rule).__name__}")
        super().__init__(margin=rule.margin, max_side=rule.max_side, clock=rule.clock,
                         threshold=rule.threshold if threshold is None else threshold)
        self.rule = rule
        self.labels = rule.labels  # the label set of the samples: the wrapped rule's
        self.n = validate_n(n)
        self.rho = validate_rho(rho)
        self.between: Between | None = None  # the decision loop's budget check between MC chunks

    @property
    def spec(self) -> MonitorSpec:
        return replace(self.rule.spec, n=self.n, rho=self.rho, threshold=self.threshold)

    @property
    def feature_key(self) -> Hashable:
        return ("mc_dropout", self.rho)

    @property
    def feature_size(self) -> int:
        return self.n

    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        return segmenter.mc_dropout(rgb_patch, self.n, self.rho, seed)

    def patch_features(self, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0, size: int | None = None,
                       trunk: Any = None, context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        """MC samples (``size`` of them, default ``n``) over the disc's box only, when the segmenter
        takes a ``window`` (the same scores: the rules read the disc's pixels and nothing else).

        Without a shared ``trunk`` (the flight path) they are drawn in chunks of ``MC_CHUNK`` samples of
        the same seeded draw, with ``self.between`` (set by the decision loop: its budget check) called
        between them, so a large ``n`` cannot overrun the time budget unseen.
        """
        n = self.n if size is None else max(int(size), self.n)
        window, box_mask = disc_box(patch.disc_mask)
        if window is None or not accepts_keyword(segmenter.mc_dropout, "window"):
            window, box_mask = None, patch.disc_mask
        if trunk is None:
            return mc_samples(segmenter, patch.rgb, n, self.rho, seed, window=window,
                              chunking=Chunking(between=self.between, clock=self.clock)), box_mask
        shared: dict[str, Any] = {"features": trunk}
        if window is None:
            return segmenter.mc_dropout(patch.rgb, n, self.rho, seed, **shared), box_mask
        return segmenter.mc_dropout(patch.rgb, n, self.rho, seed, window=window, **shared), box_mask

    @property
    def reduce_key(self) -> Hashable:
        return ("mcd_score", self.rho, self.n)

    def reduce(self, features: Any, disc_mask: np.ndarray) -> np.ndarray:
        return self.disc_score(features, disc_mask)

    def judge(self, reduced: Any) -> Judgement:
        return self.rule.judge_pixels(reduced, self.threshold)

    def disc_score(self, scores: np.ndarray, disc_mask: np.ndarray) -> np.ndarray:
        """``S`` (8, m) on the disc's pixels from samples (n' >= n, 8, h, w): what the rule judges.

        It depends on the samples and ``n`` only, so configurations that differ only in their
        rule (LHD or a CH tau) can share it (a campaign does).
        """
        validate_mask(disc_mask)
        validate_samples(scores, disc_mask.shape, self.n, labels=self.labels)
        pixel_samples = take_disc(scores[: self.n], disc_mask)  # (n, 8, m): only the disc's pixels
        return mcd_score(pixel_samples)
