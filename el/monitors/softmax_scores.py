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

- ``msp``: ``1 - max_c p_c`` (divided by its largest value ``1 - 1/C``);
- ``entropy``: ``-sum_c p_c log p_c / log C``;
- ``energy``: the segmenter returns softmax, not logits, and the free energy ``-logsumexp`` of
  log-softmax is 0 at temperature 1, so the energy is taken at temperature ``T = 2`` on the
  log-softmax: ``T log sum_c p_c^(1/T)`` (the Renyi entropy of order 1/2), over its largest value.

C is the NETWORK's class count, ``network_classes``: a network of 6 classes seen through a class map
(``el.segmentation.class_map.MappedModel``) in a 23-class label set gives 23 planes of which 17 are 0,
and its uncertainty's largest value is that of 6 classes, not 23. None: the label set's count (the
shipped system, whose network segments into its label set: 8 for UAVid). Classes nobody reaches add
nothing to the sums, so with a one-to-one map the scores are exactly the network's own softmax's. A
many-to-one map sums network classes before the monitor sees them: the uncertainty between two merged
classes is gone (the score is then a lower bound of the network's), which the monitor cannot undo.
With ``network_classes`` given the uncertainty is also capped at 1, so that it stays below the
forbidden branch whatever the map.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from el.classes.labels import LabelSet
from el.landing.forbidden import forbidden_pixels
from el.monitors.base import Judgement
from el.monitors.lhd import LHDMonitor
from el.monitors.spec import GenericSpec


def check_network_classes(network_classes: object) -> int | None:
    """``network_classes`` when it is None or an integer >= 2 (a softmax of one class has no uncertainty)."""
    if network_classes is None:
        return None
    if isinstance(network_classes, bool) or not isinstance(network_classes, int | np.integer) \
            or int(network_classes) < 2:
        raise ValueError(f"network_classes must be an integer >= 2 (the network's class count), "
                         f"got {network_classes!r}")
    return int(network_classes)


class SoftmaxScoreMonitor(LHDMonitor):
    """LHD plus the largest normalised uncertainty of the disc's pixels (see the module docstring)."""

    KIND: ClassVar[str] = ""
    DEFAULT_THRESHOLD: ClassVar[float] = 1.0
    SCORE_RANGE: ClassVar[tuple[float, float]] = (0.0, 2.0)  # uncertainty in [0, 1], 1 + a fraction above it
    PARAMS: ClassVar[dict[str, Any]] = {}

    def __init__(self, *, labels: LabelSet, network_classes: int | None = None, **kwargs: Any) -> None:
        super().__init__(labels=labels, **kwargs)
        self.network_classes = check_network_classes(network_classes)

    @property
    def classes(self) -> int:
        """C of the normalisation: the network's class count, else the label set's (module docstring)."""
        return self.labels.num_classes if self.network_classes is None else self.network_classes

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        return self.generic_spec(self.KIND)

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        """(m,) per-pixel uncertainty in [0, 1] from the softmax (C, m)."""
        raise NotImplementedError

    def capped(self, u: np.ndarray) -> np.ndarray:
        """``u`` as it is for the label set's own network; at most 1 with ``network_classes`` given."""
        return u if self.network_classes is None else np.minimum(u, 1.0)

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
        return self.capped((1.0 - pixel_scores.max(axis=0)) / (1.0 - 1.0 / self.classes))


class EntropyMonitor(SoftmaxScoreMonitor):
    """``entropy``: Shannon entropy of the worst disc pixel's softmax, over log C (C = 8 for UAVid)."""

    KIND = "entropy"

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        p = pixel_scores / np.maximum(pixel_scores.sum(axis=0, keepdims=True), 1e-12)
        logp = np.log(np.where(p > 0, p, 1.0))
        return self.capped(np.maximum(-(p * logp).sum(axis=0), 0.0) / math.log(self.classes))


class EnergyMonitor(SoftmaxScoreMonitor):
    """``energy``: free energy of the log-softmax at temperature 2 (Liu et al., 2020), normalised."""

    KIND = "energy"
    TEMPERATURE: ClassVar[float] = 2.0

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        t = self.TEMPERATURE
        p = pixel_scores / np.maximum(pixel_scores.sum(axis=0, keepdims=True), 1e-12)
        e = t * np.log(np.maximum((p ** (1.0 / t)).sum(axis=0), 1e-300))
        return self.capped(np.maximum(e, 0.0) / ((t - 1.0) * math.log(self.classes)))
