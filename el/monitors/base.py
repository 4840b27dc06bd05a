"""The runtime-monitor interface: a segmenter protocol, two small base classes, input validation.

- :class:`Monitor` is what flight needs, and all it sees: ``check(hd_image, candidate, segmenter, seed=...)``
  judges one candidate and times it, with a name, a threshold and the fitted model it rests on.
- :class:`PatchMonitor` is how the built-in monitors are written: crop the HD patch, compute its
  features, reduce them, judge. A campaign (``assurance.campaign.judging``) uses these steps to segment a
  patch once and feed every configuration; a monitor that is only a :class:`Monitor` is judged alone.

Every monitor returns a real-valued score per candidate (higher = more likely unsafe) and rejects
the candidate iff its score is above its threshold (``Monitor.accepts``).

Monitors never catch exceptions: a bad input raises ValueError and the decision loop turns any
exception into the default action (EL-R06).
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from el.base.deadline import checkpoint
from el.base.decision import Candidate, Disc, MonitorVerdict
from el.classes.labels import LabelSet
from el.monitors.patch_batch import check_batched
from el.monitors.patches import Patch, extract_patch, validate_patch_params
from el.monitors.spec import THRESHOLD, GenericSpec, MonitorSpec

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


def _num_classes(labels: LabelSet | None, array: np.ndarray, axis: int) -> int:
    """The class count a monitor checks against: its label set's, or (None) the array's own, at least 1."""
    if labels is not None:
        return labels.num_classes
    return max(1, array.shape[axis]) if array.ndim > axis else 1


def validate_scores(scores: object, shape: tuple[int, int], what: str = "scores", *,
                    labels: LabelSet | None) -> np.ndarray:
    """Check per-class scores: ndarray of shape (C, h, w), real, finite.

    C is ``labels.num_classes`` (the monitor's label set; 8 for UAVid), or, with ``labels=None``,
    whatever the array holds.
    """
    if not isinstance(scores, np.ndarray):
        raise ValueError(f"{what} must be a numpy array, got {type(scores).__name__}")
    n = _num_classes(labels, scores, 0)
    if scores.shape != (n, *shape):
        raise ValueError(f"{what} must have shape {(n, *shape)}, got {scores.shape}")
    if not np.issubdtype(scores.dtype, np.floating):
        raise ValueError(f"{what} must be floating point, got {scores.dtype}")
    if not np.isfinite(scores).all():
        raise ValueError(f"non-finite scores ({what})")
    return scores


def validate_samples(samples: object, shape: tuple[int, int], n: int, *,
                     labels: LabelSet | None) -> np.ndarray:
    """Check MC-dropout samples: ndarray of shape (n', C, h, w) with n' >= n, real, finite.

    C as in :func:`validate_scores`: ``labels.num_classes``, or the array's own with ``labels=None``.
    """
    if not isinstance(samples, np.ndarray) or samples.ndim != 4:
        got = getattr(samples, "shape", samples)
        c = "C" if labels is None else labels.num_classes
        raise ValueError(f"MC samples must be a 4-D array (n, {c}, h, w), got {got!r}")
    c = _num_classes(labels, samples, 1)
    if samples.shape[1:] != (c, *shape):
        want = f"(n, {c}, {shape[0]}, {shape[1]})"
        raise ValueError(f"MC samples must have shape {want}, got {samples.shape}")
    if samples.shape[0] < n:
        raise ValueError(f"{n} MC samples needed, got {samples.shape[0]}")
    if not np.issubdtype(samples.dtype, np.floating):
        raise ValueError(f"MC samples must be floating point, got {samples.dtype}")
    if not np.isfinite(samples[:n]).all():
        raise ValueError("non-finite scores (MC samples)")
    return samples


@dataclass(frozen=True)
class Judgement:
    """A monitor's word on one candidate: its score (higher = more likely unsafe), verdict and why."""

    score: float
    accepted: bool
    reason: str


@dataclass(frozen=True)
class CandidateContext:
    """What the decision loop knows about a candidate besides its HD patch (for monitors that use it).

    ``frame_probs``: the frame's softmax at the working resolution, (8, h, w); ``frame_size``: the
    full-resolution ``(width, height)``; ``candidate``: the ranked candidate being judged;
    ``frame_checked``: ``frame_probs`` was validated already (``validate_scores``: a monitor judging every
    candidate of a frame checks the frame once, not once per candidate).
    """

    candidate: Candidate
    frame_probs: np.ndarray
    frame_size: tuple[int, int]
    frame_checked: bool = False


def validate_threshold(threshold: object) -> float:
    """A monitor threshold: a finite real number."""
    if isinstance(threshold, bool) or not isinstance(threshold, int | float | np.floating) \
            or not math.isfinite(float(threshold)):
        raise ValueError(f"threshold must be a finite number, got {threshold!r}")
    return float(threshold)


def check_threshold_range(threshold: float, score_range: tuple[float, float], who: str) -> float:
    """``threshold`` when it lies in [lo, hi) of ``score_range``, else ValueError naming the monitor and the range."""
    lo, hi = score_range
    if not lo <= threshold < hi:
        effect = "accept every candidate" if threshold >= hi else "reject every candidate"
        raise ValueError(f"{who}: threshold {threshold:g} lies outside the monitor's score range [{lo:g}, {hi:g}] "
                         f"(it would {effect}); give a threshold in [{lo:g}, {hi:g})")
    return threshold


class Monitor(ABC):
    """A runtime monitor as the decision loop sees it: it judges one candidate on the HD frame.

    A verdict carries a real-valued score (higher = more likely unsafe), and the candidate is rejected
    **iff score > threshold** (:meth:`accepts`). A score may be ``+inf`` (always rejected), never NaN.

    Parameters
    ----------
    threshold : float or None
        None: the monitor's :attr:`DEFAULT_THRESHOLD` (for the paper's rules, the one that gives the
        paper's verdicts); a calibration card sets another.
    """

    DEFAULT_THRESHOLD: ClassVar[float] = 0.0
    #: The finite scores this monitor can give, [lo, hi] (``+inf`` aside). A threshold must lie in [lo, hi): at
    #: or above hi it accepts every candidate, below lo it rejects every one; either way the monitor would run
    #: under its name without judging. A plugin that does not declare its range is not checked.
    SCORE_RANGE: ClassVar[tuple[float, float]] = (-math.inf, math.inf)

    #: SHA-256 of the fitted file this monitor's scores rest on (a learned model); None for a rule. A
    #: monitor with a model sets or overrides it: calibration cards and campaign manifests record it,
    #: since a threshold calibrated on one model means nothing on another.
    model_sha256: str | None = None

    def __init__(self, *, threshold: float | None = None) -> None:
        self.threshold = check_threshold_range(
            validate_threshold(self.DEFAULT_THRESHOLD if threshold is None else threshold), self.SCORE_RANGE,
            f"monitor {type(self).__name__}")

    @property
    @abstractmethod
    def spec(self) -> MonitorSpec | GenericSpec:
        """The configuration this monitor implements."""

    @property
    def name(self) -> str:
        """Canonical configuration name, e.g. ``lhd+ch:tau=0.25``."""
        return self.spec.name

    def accepts(self, score: float) -> bool:
        """The verdict at this monitor's threshold: accepted iff ``score <= threshold``."""
        if math.isnan(score):
            raise ValueError(f"{self.name}: non-finite score (NaN)")
        return not score > self.threshold

    def check_network(self, segmenter: Any) -> None:
        """Refuse a segmentation network this monitor was not fitted on (a rule fits every network)."""
        return None

    @abstractmethod
    def check(
        self, hd_image: np.ndarray, candidate: Candidate | Disc, segmenter: PatchSegmenter, *, seed: int = 0,
        context: CandidateContext | None = None,
    ) -> MonitorVerdict:
        """Judge one candidate (or Disc) on the HD image; ``seconds`` is the time it took.

        ``seed`` drives any randomness (MC dropout); ``context`` is for monitors that read the frame's
        segmentation. Raises on bad input or a segmenter that returns the wrong shape or non-finite scores.
        """

    def check_many(
        self, hd_image: np.ndarray, candidates: Sequence[Candidate | Disc], segmenter: PatchSegmenter, *,
        seeds: Sequence[int], contexts: Sequence[CandidateContext | None] | None = None,
    ) -> list[MonitorVerdict]:
        """Judge several candidates of one frame: for each k, the verdict ``check`` gives candidate k with
        ``seed=seeds[k]`` and ``context=contexts[k]`` (None: no contexts).

        A monitor may share work between the candidates (:class:`PatchMonitor` segments their HD patches in few
        batched passes); this default judges them one at a time. A score walk judges every candidate anyway.
        """
        contexts = batch_arguments(candidates, seeds, contexts)
        return [self.check(hd_image, c, segmenter, seed=int(s), context=x)
                for c, s, x in zip(candidates, seeds, contexts, strict=True)]


class PatchMonitor(Monitor):
    """A monitor that judges the segmented HD patch around a candidate, in steps a campaign can share:

    1. **features** of a patch (:meth:`patch_features`), described by :attr:`feature_key`: monitors with
       equal keys compute the same features (of :attr:`feature_size` samples);
    2. a **score** from the features: :meth:`reduce` (the same for monitors with equal
       :attr:`reduce_key`), then :meth:`judge`, real-valued, higher = more likely unsafe;
    3. the threshold of :class:`Monitor`.

    Parameters
    ----------
    margin : float, default 0.25
        Context around the disc, as a fraction of its radius (see ``extract_patch``).
    max_side : int or None, default None
        Downscale patches whose longer side exceeds this (None: always full resolution).
    clock : callable returning seconds, default ``time.perf_counter``
        Injectable for tests of time budgets.
    threshold : float or None
        See :class:`Monitor`.

    Subclasses implement ``spec``, ``feature_key``, ``features`` and ``judge`` (pure and untimed);
    a registered monitor also takes ``threshold`` and the patch keywords in its constructor.
    """

    def __init__(
        self, *, margin: float = 0.25, max_side: int | None = None, clock: Clock = time.perf_counter,
        threshold: float | None = None,
    ) -> None:
        super().__init__(threshold=threshold)
        self.margin = margin
        self.max_side = max_side
        self.clock = clock
        validate_patch_params(margin, max_side)  # now, not at the first candidate

    # -- what a subclass defines -------------------------------------------------------------
    @property
    @abstractmethod
    def feature_key(self) -> Hashable:
        """What ``features`` computes, minus its size: monitors with equal keys share features
        (``("softmax",)``, or ``("mc_dropout", rho)`` with ``feature_size`` samples needed)."""

    @abstractmethod
    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        """Segment a patch: softmax (8, h, w), or MC samples (n, 8, h, w) for MCD monitors."""


    @abstractmethod
    def judge(self, reduced: Any) -> Judgement:
        """Score, verdict at :attr:`threshold` and reason, from :meth:`reduce`'s output. Validates."""

    def softmax_features(self, probs: np.ndarray, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0,
                         context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        """What :meth:`patch_features` gives, from the patch's softmax ``probs`` (C, h, w) computed already.

        Monitors whose features rest on the patch's softmax define it (and build ``patch_features`` on it), so
        that :meth:`check_many` can segment every candidate's patch in few batched passes; the others do not
        (:meth:`batches_softmax` is then False and ``check_many`` judges one candidate at a time).
        """
        raise NotImplementedError(f"{type(self).__name__} does not compute its features from the patch softmax")

    def batches_softmax(self) -> bool:
        """Whether :meth:`check_many` may segment the patches in batches: this class's :meth:`softmax_features`
        is defined where its :meth:`patch_features` is, or below (a subclass that overrides ``patch_features``
        alone computes something else, and is judged one candidate at a time)."""
        own = _defined_in(type(self), "softmax_features")
        return own is not PatchMonitor and issubclass(own, _defined_in(type(self), "patch_features"))

    def check_many(
        self, hd_image: np.ndarray, candidates: Sequence[Candidate | Disc], segmenter: PatchSegmenter, *,
        seeds: Sequence[int], contexts: Sequence[CandidateContext | None] | None = None,
    ) -> list[MonitorVerdict]:
        """The verdicts of :meth:`check` on several candidates of one frame, their HD patches segmented in few
        batched passes when the monitor's features rest on the softmax (:mod:`el.monitors.patch_batch`)."""
        if not self.batches_softmax():
            return super().check_many(hd_image, candidates, segmenter, seeds=seeds, contexts=contexts)
        return check_batched(self, hd_image, candidates, segmenter, seeds=seeds,
                             contexts=batch_arguments(candidates, seeds, contexts), validate=validate_scores)

    # -- overridable steps -------------------------------------------------------------------
    @property
    def feature_size(self) -> int:
        """How many samples of the features this monitor needs (1 unless it draws several)."""
        return 1

    def patch_features(self, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0, size: int | None = None,
                       trunk: Any = None, context: CandidateContext | None = None
                       ) -> tuple[Any, np.ndarray]:
        """Features of a patch and the disc mask that goes with them.

        ``size``: samples to draw (>= :attr:`feature_size`; a campaign draws the largest once);
        ``trunk``: the segmenter's ``patch_trunk`` of this patch, when the caller shares it;
        ``context``: the candidate and the frame's segmentation (see :class:`CandidateContext`).
        """
        return self.features(patch.rgb, segmenter, seed=seed), patch.disc_mask

    @property
    def reduce_key(self) -> Hashable:
        """Monitors with equal keys compute the same :meth:`reduce` (default: shared with none)."""
        return ("own", id(self))

    def reduce(self, features: Any, disc_mask: np.ndarray) -> Any:
        """The part of scoring that monitors may share (default: the features and mask as they are)."""
        return features, disc_mask

    # -- shared behaviour --------------------------------------------------------------------
    def threshold_note(self, score: float, accepted: bool) -> str:
        """Reason suffix when the threshold, not the rule's default, decided."""
        return f"score {score:.6g} {'<=' if accepted else '>'} threshold {self.threshold:.6g}"

    def patch(self, hd_image: np.ndarray, disc: Disc | Candidate) -> Patch:
        """The HD patch this monitor looks at for a disc (or candidate)."""
        return extract_patch(hd_image, disc, margin=self.margin, max_side=self.max_side)

    def decide(self, scores: Any, disc_mask: np.ndarray) -> tuple[bool, str]:
        """The verdict on features already computed: ``(accepted, reason)``."""
        j = self.judge(self.reduce(scores, disc_mask))
        return j.accepted, j.reason

    def score(self, scores: Any, disc_mask: np.ndarray) -> float:
        """The score on features already computed (higher = more likely unsafe)."""
        return self.judge(self.reduce(scores, disc_mask)).score

    def check_scores(self, scores: Any, disc_mask: np.ndarray) -> MonitorVerdict:
        """Features-level entry: the verdict on scores already computed for a patch.

        ``seconds`` is the time of the rule alone; a campaign adds the cost of the patch and
        of the segmentation it shares.
        """
        t0 = self.clock()
        j = self.judge(self.reduce(scores, disc_mask))
        return self._verdict(j, self.clock() - t0)

    def check(
        self, hd_image: np.ndarray, candidate: Candidate | Disc, segmenter: PatchSegmenter, *, seed: int = 0,
        context: CandidateContext | None = None,
    ) -> MonitorVerdict:
        """Crop, segment and judge one candidate (or Disc) on the HD image; ``seconds`` is the total.

        ``seed`` drives MC dropout (ignored by deterministic monitors); ``context`` is for monitors
        that read the frame's segmentation. Raises on bad input or a segmenter that returns the
        wrong shape or non-finite scores.
        """
        t0 = self.clock()
        # the decision's deadline (el.base.deadline), before and after the patch's segmentation
        checkpoint("monitoring")
        patch = self.patch(hd_image, candidate)
        features, mask = self.patch_features(patch, segmenter, seed=seed, context=context)
        checkpoint("monitoring")
        j = self.judge(self.reduce(features, mask))
        return self._verdict(j, self.clock() - t0)

    def _verdict(self, j: Judgement, seconds: float) -> MonitorVerdict:
        if math.isnan(j.score):
            raise ValueError(f"{self.name}: non-finite score (NaN)")
        return MonitorVerdict(self.name, bool(j.accepted), j.reason, seconds, float(j.score), self.threshold)

    def generic_spec(self, kind: str, **params: Any) -> GenericSpec:
        """The spec of a registered monitor: its parameters (None ones left out), then the threshold
        when it is not the default (so one configuration has one name)."""
        items = [(k, v) for k, v in params.items() if v is not None]
        if self.threshold != self.DEFAULT_THRESHOLD:
            items.append((THRESHOLD, self.threshold))
        return GenericSpec(kind, tuple(items))

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.name!r}, margin={self.margin}, max_side={self.max_side}, "
                f"threshold={self.threshold})")


def batch_arguments(candidates: Sequence[Any], seeds: Sequence[int],
                    contexts: Sequence[CandidateContext | None] | None) -> list[CandidateContext | None]:
    """The contexts of ``check_many`` (None: one None per candidate), after checking there is one seed and one
    context per candidate."""
    contexts = [None] * len(candidates) if contexts is None else list(contexts)
    if not len(seeds) == len(contexts) == len(candidates):
        raise ValueError(f"check_many: {len(candidates)} candidates, {len(seeds)} seeds and {len(contexts)} contexts")
    return contexts


def _defined_in(cls: type, name: str) -> type:
    """The class of ``cls``'s MRO that defines attribute ``name``."""
    return next(k for k in cls.__mro__ if name in k.__dict__)


def format_counts(counts: dict[str, int]) -> str:
    """``{"road": 37, "static_car": 3}`` -> ``"road (37 px), static_car (3 px)"``, largest first."""
    items = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    return ", ".join(f"{k} ({v} px)" for k, v in items)
