"""Softmax-uncertainty monitors of the HD disc: maximum softmax probability, entropy and energy.

These are the per-pixel scores of the pytorch-ood family (MSP: Hendrycks & Gimpel, ICLR 2017;
entropy; energy: Liu et al., NeurIPS 2020), written here in a few lines instead of depending on
``pytorch-ood``: its detectors score one image-level output per sample, not the pixels of a disc, and
the package would add a second pinned torch stack to the flight code for three one-line formulas.

Each monitor is LHD plus an uncertainty term, on the disc's HD softmax (the same features and disc
pixels as LHD and CH, so a campaign computes them once for all of them):

- a disc with a pixel whose top class is forbidden scores ``1 + fraction of such pixels`` (> 1);
- otherwise its score is the largest per-pixel uncertainty ``u`` in the disc, normalised to [0, 1].

The default threshold 1 is therefore LHD's verdict exactly; a calibrated threshold below 1 also
rejects discs with an uncertain pixel. ``u`` per monitor:

- ``msp``: ``1 - max_c p_c`` (divided by its largest value ``1 - 1/C``, C = 8 classes for UAVid: the
  monitor's label set's count);
- ``entropy``: ``-sum_c p_c log p_c / log C``;
- ``energy``: the segmenter returns softmax, not logits, and the free energy ``-logsumexp`` of
  log-softmax is 0 at temperature 1, so the energy is taken at temperature ``T = 2`` on the
  log-softmax: ``T log sum_c p_c^(1/T)`` (the Renyi entropy of order 1/2), over its largest value.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from el.forbidden import forbidden_pixels
from el.monitors.base import Judgement
from el.monitors.lhd import LHDMonitor
from el.monitors.spec import GenericSpec


class SoftmaxScoreMonitor(LHDMonitor):
    """LHD plus the largest normalised uncertainty of the disc's pixels (see the module docstring)."""

    KIND: ClassVar[str] = ""
    DEFAULT_THRESHOLD: ClassVar[float] = 1.0
    SCORE_RANGE: ClassVar[tuple[float, float]] = (0.0, 2.0)  # uncertainty in [0, 1], 1 + a fraction above it
    PARAMS: ClassVar[dict[str, Any]] = {}

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        return self.generic_spec(self.KIND)

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        """(m,) per-pixel uncertainty in [0, 1] from the softmax (8, m)."""
        raise NotImplementedError

    def judge_pixels(self, pixel_scores: np.ndarray, threshold: float | None = None) -> Judgement:
        m = pixel_scores.shape[1]
        if m == 0:
            return Judgement(math.inf, False, "empty disc: no pixel to check")
        forbidden = forbidden_pixels(pixel_scores, self.labels)
        k = int(np.count_nonzero(forbidden))
        if k:
            score, what = 1.0 + k / m, f"forbidden top class on {k} of {m} px"
        else:
            u = self.uncertainty(np.clip(pixel_scores.astype(np.float64), 0.0, 1.0))
            score, what = float(u.max()), f"largest {self.KIND} uncertainty {float(u.max()):.4f} ({m} px)"
        accepted = self.accepts(score)
        return Judgement(score, accepted, f"{what}; {self.threshold_note(score, accepted)}")


class MSPMonitor(SoftmaxScoreMonitor):
    """``msp``: 1 - maximum softmax probability of the worst disc pixel (Hendrycks & Gimpel, 2017)."""

    KIND = "msp"

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        return (1.0 - pixel_scores.max(axis=0)) / (1.0 - 1.0 / self.labels.num_classes)


class EntropyMonitor(SoftmaxScoreMonitor):
    """``entropy``: Shannon entropy of the worst disc pixel's softmax, over log 8."""

    KIND = "entropy"

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        p = pixel_scores / np.maximum(pixel_scores.sum(axis=0, keepdims=True), 1e-12)
        logp = np.log(np.where(p > 0, p, 1.0))
        return np.maximum(-(p * logp).sum(axis=0), 0.0) / math.log(self.labels.num_classes)


class EnergyMonitor(SoftmaxScoreMonitor):
    """``energy``: free energy of the log-softmax at temperature 2 (Liu et al., 2020), normalised."""

    KIND = "energy"
    TEMPERATURE: ClassVar[float] = 2.0

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        t = self.TEMPERATURE
        p = pixel_scores / np.maximum(pixel_scores.sum(axis=0, keepdims=True), 1e-12)
        e = t * np.log(np.maximum((p ** (1.0 / t)).sum(axis=0), 1e-300))
        return np.maximum(e, 0.0) / ((t - 1.0) * math.log(self.labels.num_classes))
