"""The runtime-monitor interface: a segmenter protocol, one small base class, input validation.

Two levels, as pytorch-ood's detectors (STYLE.md):

- ``Monitor.check(hd_image, candidate, segmenter, seed=...)`` does everything for one candidate
  (crop the HD patch, segment it, apply the rule) and times it: what the decision loop calls.
- ``Monitor.check_scores(scores, disc_mask)`` applies the rule to scores already computed
  (``Monitor.features(...)``): a campaign segments a patch once and feeds every configuration.

Monitors never catch exceptions: a bad input raises ValueError and the decision loop turns any
exception into the default action (EL-R06).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from el.decision import Candidate, Disc, MonitorVerdict
from el.labels import NUM_CLASSES
from el.monitors.patches import Patch, extract_patch, validate_patch_params

if TYPE_CHECKING:
    from el.monitors.spec import MonitorSpec

Clock = Callable[[], float]


@runtime_checkable
class PatchSegmenter(Protocol):
    """What a monitor needs from a segmentation model (``el.segmentation.inference.Segmenter``).

    ``predict_patch(rgb_patch)``
        ``rgb_patch``: ndarray (h, w, 3) uint8. Returns the softmax, ndarray (8, h, w) float32,
        at the patch's own resolution, deterministic (dropout off).
    ``mc_dropout(rgb_patch, n, keep_prob, seed)``
        Returns ``n`` softmax samples with dropout active, ndarray (n, 8, h, w) float32, run as one
        batch. ``keep_prob`` is rho (drop probability ``1 - rho``). Contract: deterministic for a
        given ``seed``, and **prefix-consistent**: ``mc_dropout(p, 10, r, s)`` equals
        ``mc_dropout(p, 30, r, s)[:10]``, so a campaign can draw the largest ``n`` once and give its
        prefix to the smaller configurations (``MCDMonitor.check_scores`` slices to its ``n``).
        Drawing each sample's dropout masks in sample order from one generator seeded with ``seed``
        gives this property.
    """

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray: ...

    def mc_dropout(self, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int) -> np.ndarray: ...


def validate_mask(disc_mask: object) -> np.ndarray:
    """Check a disc mask: ndarray of shape (h, w), bool."""
    if not isinstance(disc_mask, np.ndarray) or disc_mask.ndim != 2:
        got = getattr(disc_mask, "shape", disc_mask)
        raise ValueError(f"disc_mask must be a 2-D numpy array, got {got!r}")
    if disc_mask.dtype != np.bool_:
        raise ValueError(f"disc_mask must be bool, got {disc_mask.dtype}")
    return disc_mask


def validate_scores(scores: object, shape: tuple[int, int], what: str = "scores") -> np.ndarray:
    """Check per-class scores: ndarray of shape (8, h, w), real, finite."""
    if not isinstance(scores, np.ndarray):
        raise ValueError(f"{what} must be a numpy array, got {type(scores).__name__}")
    if scores.shape != (NUM_CLASSES, *shape):
        raise ValueError(f"{what} must have shape {(NUM_CLASSES, *shape)}, got {scores.shape}")
    if not np.issubdtype(scores.dtype, np.floating):
        raise ValueError(f"{what} must be floating point, got {scores.dtype}")
    if not np.isfinite(scores).all():
        raise ValueError(f"non-finite scores ({what})")
    return scores


def validate_samples(samples: object, shape: tuple[int, int], n: int) -> np.ndarray:
    """Check MC-dropout samples: ndarray of shape (n', 8, h, w) with n' >= n, real, finite."""
    if not isinstance(samples, np.ndarray) or samples.ndim != 4:
        got = getattr(samples, "shape", samples)
        raise ValueError(f"MC samples must be a 4-D array (n, {NUM_CLASSES}, h, w), got {got!r}")
    if samples.shape[1:] != (NUM_CLASSES, *shape):
        want = f"(n, {NUM_CLASSES}, {shape[0]}, {shape[1]})"
        raise ValueError(f"MC samples must have shape {want}, got {samples.shape}")
    if samples.shape[0] < n:
        raise ValueError(f"{n} MC samples needed, got {samples.shape[0]}")
    if not np.issubdtype(samples.dtype, np.floating):
        raise ValueError(f"MC samples must be floating point, got {samples.dtype}")
    if not np.isfinite(samples[:n]).all():
        raise ValueError("non-finite scores (MC samples)")
    return samples


class Monitor(ABC):
    """A runtime monitor: judges one candidate's safe disc on the segmented HD patch.

    Parameters
    ----------
    margin : float, default 0.25
        Context around the disc, as a fraction of its radius (see ``extract_patch``).
    max_side : int or None, default None
        Downscale patches whose longer side exceeds this (None: always full resolution).
    clock : callable returning seconds, default ``time.perf_counter``
        Injectable for tests of time budgets.

    Subclasses implement ``spec``, ``features`` and ``decide``; ``decide`` is pure and untimed.
    """

    def __init__(
        self, *, margin: float = 0.25, max_side: int | None = None, clock: Clock = time.perf_counter
    ) -> None:
        self.margin = margin
        self.max_side = max_side
        self.clock = clock
        validate_patch_params(margin, max_side)  # now, not at the first candidate

    # -- what a subclass defines -------------------------------------------------------------
    @property
    @abstractmethod
    def spec(self) -> MonitorSpec:
        """The configuration this monitor implements."""

    @property
    @abstractmethod
    def feature_key(self) -> Hashable:
        """What ``features`` computes, minus the size of an MC batch: monitors with equal keys can
        share features (``("softmax",)``, or ``("mc_dropout", rho)`` with ``n`` samples needed)."""

    @abstractmethod
    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        """Segment a patch: softmax (8, h, w), or MC samples (n, 8, h, w) for MCD monitors."""

    @abstractmethod
    def decide(self, scores: np.ndarray, disc_mask: np.ndarray) -> tuple[bool, str]:
        """The rule on features already computed: ``(accepted, reason)``. Validates its inputs."""

    # -- shared behaviour --------------------------------------------------------------------
    @property
    def name(self) -> str:
        """Canonical configuration name, e.g. ``lhd+ch:tau=0.25``."""
        return self.spec.name

    def patch(self, hd_image: np.ndarray, disc: Disc | Candidate) -> Patch:
        """The HD patch this monitor looks at for a disc (or candidate)."""
        return extract_patch(hd_image, disc, margin=self.margin, max_side=self.max_side)

    def check_scores(self, scores: np.ndarray, disc_mask: np.ndarray) -> MonitorVerdict:
        """Features-level entry: the verdict on scores already computed for a patch.

        ``seconds`` is the time of the rule alone; a campaign adds the cost of the patch and
        of the segmentation it shares.
        """
        t0 = self.clock()
        accepted, reason = self.decide(scores, disc_mask)
        return MonitorVerdict(self.name, bool(accepted), reason, self.clock() - t0)

    def check(
        self, hd_image: np.ndarray, candidate: Candidate | Disc, segmenter: PatchSegmenter, *, seed: int = 0
    ) -> MonitorVerdict:
        """Crop, segment and judge one candidate (or Disc) on the HD image; ``seconds`` is the total.

        ``seed`` drives MC dropout (ignored by deterministic monitors). Raises on bad input or a
        segmenter that returns the wrong shape or non-finite scores.
        """
        t0 = self.clock()
        patch = self.patch(hd_image, candidate)
        scores, mask = self.patch_scores(patch, segmenter, seed=seed)
        accepted, reason = self.decide(scores, mask)
        return MonitorVerdict(self.name, bool(accepted), reason, self.clock() - t0)

    def patch_scores(self, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0
                     ) -> tuple[np.ndarray, np.ndarray]:
        """The scores :meth:`decide` judges for a patch, and the disc mask that goes with them.

        By default :meth:`features` of the whole patch and its mask; a monitor may restrict both to
        the disc's box when the segmenter can (MCD does).
        """
        return self.features(patch.rgb, segmenter, seed=seed), patch.disc_mask

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, margin={self.margin}, max_side={self.max_side})"


def format_counts(counts: dict[str, int]) -> str:
    """``{"road": 37, "static_car": 3}`` -> ``"road (37 px), static_car (3 px)"``, largest first."""
    items = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    return ", ".join(f"{k} ({v} px)" for k, v in items)
