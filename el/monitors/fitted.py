"""The base of the fitted feature-space detectors (``mahalanobis``, ``gmm``, ``outside_box``): record and monitor.

Each scores a candidate by how far its feature vector lies from those of the truly safe candidates of a
training split (the "in-distribution" of a landing monitor: a candidate whose disc holds no forbidden
ground-truth pixel). The feature vector is the learned monitor's (:func:`el.monitors.learned.candidate_features`:
statistics of the disc on the frame's and the HD patch's softmax, geometry, context), which the segmentation pass
already computed: no second network pass, no torch, and it exists for every network, an ONNX one included.
(The benchmark of Guerin et al. (UAI 2024) fits these detectors on a network's penultimate-layer activations;
the segmentation seam exposes no per-candidate trunk activations for an ONNX network, so this repository fits them
on the candidate features every network yields; see docs/monitor-benchmark.md.)

A fitted record is plain JSON, hashed like the learned monitor's model (:class:`el.base.records.HashedRecord`, read
through the bounded reader ``el.base.userfiles``; no pickle): ``{"format", "body", "sha256"}`` whose body holds the
family, the feature names, the standardisation (``mean``, ``scale``), the family's parameters (``params``), the
default threshold and how it was chosen (``criterion``), and the network it was fitted on (``weights``).
``assurance.fitting.detectors`` writes it (``uav-el benchmark --fit``). Inference is numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from el.base.errors import UavElError
from el.base.records import HashedRecord
from el.classes.labels import LabelSet
from el.monitors.base import CandidateContext, Judgement, PatchSegmenter
from el.monitors.learned import base_features, candidate_features, feature_columns
from el.monitors.lhd import LHDMonitor
from el.monitors.patches import Patch
from el.monitors.spec import GenericSpec

DETECTOR_FORMAT = "uav-el-candidate-detector/1"


class DetectorModelError(UavElError, ValueError):
    """A fitted detector record that cannot be used (missing, unreadable, altered, inconsistent, another family)."""


@dataclass(frozen=True)
class DetectorRecord(HashedRecord):
    """A checked fitted-detector record (:func:`load_detector`)."""

    FORMAT: ClassVar[str] = DETECTOR_FORMAT
    WHAT: ClassVar[str] = "fitted detector record"
    ERROR: ClassVar[type[ValueError]] = DetectorModelError

    family: str
    mean: np.ndarray
    scale: np.ndarray
    columns: np.ndarray
    params: dict[str, np.ndarray]
    labels: LabelSet

    @property
    def threshold(self) -> float:
        return float(self.body["threshold"])

    @property
    def width(self) -> int:
        return len(base_features(self.labels))

    def standardise(self, x: np.ndarray) -> np.ndarray:
        """The record's standardised features of rows ``x`` (n, width) or one row (width,)."""
        x = np.asarray(x, np.float64)
        if x.shape[-1] != self.width:
            raise ValueError(f"expected candidate feature vectors of {self.width} values, got {x.shape}")
        return (x[..., self.columns] - self.mean) / self.scale


def _array(body: dict[str, Any], key: str, shape: tuple[int, ...]) -> np.ndarray:
    v = np.asarray(body[key], dtype=np.float64)
    if v.shape != shape or not np.isfinite(v).all():
        raise ValueError(f"{key} must be finite numbers of shape {shape}, got {v.shape}")
    return v


def load_detector(path: str | Path, family: str, shapes: dict[str, tuple[str, ...]], *,
                  labels: LabelSet) -> DetectorRecord:
    """Read and check a fitted record of ``family``; ``shapes``: each parameter's shape in ``d`` (features) and
    ``k`` (components), e.g. ``{"means": ("k", "d")}``. Raises :class:`DetectorModelError` (one line)."""
    p = Path(path)
    hint = f" (fit one with: uav-el benchmark --fit TRAIN --data VAL --out DIR, which writes {family}.json)"
    body, digest = DetectorRecord.read_body(p, hint=hint)
    try:
        if body.get("family") != family:
            raise ValueError(f"it holds a {body.get('family')!r} detector, not {family!r}")
        names = tuple(body["features"])
        columns = feature_columns(names, 0, labels)
        d = len(names)
        k = int(body.get("components", 1))
        mean, scale = _array(body, "mean", (d,)), _array(body, "scale", (d,))
        if (scale <= 0).any():
            raise ValueError("scale must be positive")
        raw = body["params"]
        params = {key: _array(raw, key, tuple(d if s == "d" else k for s in shape)) for key, shape in shapes.items()}
        if not math.isfinite(float(body["threshold"])):
            raise ValueError("threshold must be finite")
    except (KeyError, TypeError, ValueError) as exc:
        raise DetectorModelError(f"{p}: inconsistent {family} detector record ({exc})") from None
    return DetectorRecord(str(p), digest, body, family, mean, scale, columns, params, labels)


class FittedDetectorMonitor(LHDMonitor):
    """A candidate-feature detector read from its fitted record (``model=FILE``, required).

    Subclasses set :attr:`KIND`, :attr:`SHAPES` and :meth:`distance` (a score of standardised rows, higher = farther
    from the safe training candidates). Needs the candidate's context, as the learned monitor; the record's threshold
    is the default; the segmenter must be the network the record was fitted on.
    """

    KIND: ClassVar[str] = ""
    SHAPES: ClassVar[dict[str, tuple[str, ...]]] = {}
    PARAMS: ClassVar[dict[str, Any]] = {"model": str}
    REQUIRED: ClassVar[tuple[str, ...]] = ("model",)
    #: Any threshold a record or a criterion chose: one below every score (reject all) included.
    SCORE_RANGE: ClassVar[tuple[float, float]] = (-math.inf, math.inf)

    def __init__(self, *, labels: LabelSet, model: str, threshold: float | None = None, **common: Any) -> None:
        self.model_path = model
        self.record = load_detector(model, self.KIND, self.SHAPES, labels=labels)
        self.DEFAULT_THRESHOLD = self.record.threshold  # type: ignore[misc]  # per record, not per class
        super().__init__(threshold=threshold, labels=labels, **common)

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        return self.generic_spec(self.KIND, model=self.model_path)

    @property
    def model_sha256(self) -> str:
        return self.record.sha256

    @property
    def feature_key(self) -> Hashable:
        return ("candidate_features", self.margin, self.max_side)  # shared by every fitted detector

    def check_network(self, segmenter: Any) -> None:
        self.record.check_network(segmenter)

    def patch_features(self, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0, size: int | None = None,
                       trunk: Any = None, context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        probs, _ = super().patch_features(patch, segmenter, seed=seed, trunk=trunk)
        return self.softmax_features(probs, patch, segmenter, seed=seed, context=context)

    def softmax_features(self, probs: np.ndarray, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0,
                         context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        if context is None:
            raise ValueError(f"the {self.KIND} detector needs the candidate's context (frame softmax)")
        self.check_network(segmenter)
        return candidate_features(probs, patch, context, margin=self.margin, labels=self.labels), patch.disc_mask

    @property
    def reduce_key(self) -> Hashable:
        return (self.KIND, self.record.sha256)

    def reduce(self, features: Any, disc_mask: np.ndarray) -> float:
        x = np.asarray(features, dtype=np.float64)
        if x.shape != (self.record.width,) or not np.isfinite(x).all():
            raise ValueError(f"{self.KIND}: expected {self.record.width} finite features, got {x.shape}")
        return float(self.distance(self.record.standardise(x)[None, :])[0])

    def distance(self, z: np.ndarray) -> np.ndarray:
        """(n,) scores of standardised rows ``z`` (n, d); higher = farther from the safe training candidates."""
        raise NotImplementedError

    def judge(self, reduced: Any) -> Judgement:
        score = float(reduced)
        accepted = self.accepts(score)
        return Judgement(score, accepted, f"{self.KIND} score {score:.4g} {'<=' if accepted else '>'} "
                                          f"threshold {self.threshold:.4g}")

    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        raise ValueError(f"the {self.KIND} detector judges candidates in context (check(..., context=...))")
