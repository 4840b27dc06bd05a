"""``learned``: a small classifier on per-candidate features, trained on train-split candidates.

Score = the classifier's probability that the candidate is truly unsafe (its disc holds a forbidden
ground-truth pixel); rejected iff score > threshold. The threshold of the model file is the default
(chosen on validation data by ``uav-el fit-monitor``: the largest one whose recall of unsafe candidates
is >= 0.95); ``learned:threshold=X`` or a calibration card sets another.

Features (:data:`BASE_FEATURES`, per candidate): the same four statistics of the disc on the frame's
softmax (``lr_*``, working resolution, from :class:`CandidateContext`) and on the HD patch's softmax
(``hd_*``): the largest and mean forbidden probability (sum of the forbidden classes), the share of
pixels whose top class is forbidden, and the largest (top forbidden - top safe) margin; the distance
from the disc's edge to the nearest predicted-forbidden pixel of the HD patch, in radii (< 0 inside
the disc); the candidate's row (over the frame height), radius (over the frame height) and hazard
(:data:`CORE_FEATURES`); then (:data:`CONTEXT_FEATURES`) the largest and mean forbidden probability of
the frame's softmax in discs of 1.5, 2 and 3 radii around the candidate, and the largest probability
of each forbidden class in the disc, on the HD patch and on the frame. (The context features raised
the held-out AUROC from 0.772 to 0.797 on the validation candidates of model ``0d3dab88``; a ring on
the HD patch, probability quantiles and entropies added nothing there.) Optional
(:data:`MCD_FEATURES`, when the model file asks for ``mcd.n`` > 0 samples): the mean and largest
standard deviation of the forbidden probability over MC-dropout samples in the disc.

"Forbidden" is the label set's word (``labels``, given by the caller); the per-class
features are named after its forbidden classes (:func:`base_features`), so a model is fitted and
flown with one label set.

The model file is plain JSON (no pickle), a card like the calibration card: ``{"format", "body",
"sha256"}`` with the SHA-256 of the body's canonical JSON; the body holds the feature names, the
standardisation (``mean``, ``scale``), the logistic regression's ``coef`` and ``intercept``, the
threshold and what the model rests on (training data hash, segmentation weights hash, sklearn
version). Inference is numpy only: the flight code does not import scikit-learn. A missing, altered
or inconsistent file raises :class:`LearnedModelError` when the monitor is built, which the decision
loop turns into the default action with that reason.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from el.base.errors import LearnedModelError
from el.base.records import HashedRecord
from el.classes.labels import UAVID, LabelSet
from el.geometry.discs import window_sq_distances
from el.landing.forbidden import top_scores
from el.monitors.base import CandidateContext, Judgement, PatchSegmenter, validate_scores
from el.monitors.lhd import LHDMonitor, take_disc
from el.monitors.patches import Patch
from el.monitors.spec import GenericSpec

MODEL_FORMAT = "uav-el-learned-monitor/1"
DEFAULT_MODEL = Path(__file__).resolve().parent / "data" / "learned.json"

_DISC_STATS = ("max_forbidden_p", "mean_forbidden_p", "forbidden_fraction", "max_margin")
CONTEXT_SCALES: tuple[float, ...] = (1.5, 2.0, 3.0)  # context discs, in radii of the safe disc
_FORBIDDEN = np.array(UAVID.forbidden_ids)  # UAVid's, the shipped model's set (tests)
CORE_FEATURES: tuple[str, ...] = (
    *(f"lr_{s}" for s in _DISC_STATS),
    *(f"hd_{s}" for s in _DISC_STATS),
    "edge_distance_radii", "row", "radius", "hazard",
)


def context_features(labels: LabelSet) -> tuple[str, ...]:
    """The context feature names (:data:`CONTEXT_FEATURES` for UAVid): per forbidden class of ``labels``."""
    names = tuple(labels.names[i] for i in labels.forbidden_ids)
    return (
        *(f"ctx{k:g}_{s}" for k in CONTEXT_SCALES for s in ("max_forbidden_p", "mean_forbidden_p")),
        *(f"hd_max_p_{c}" for c in names),
        *(f"lr_max_p_{c}" for c in names),
    )


def base_features(labels: LabelSet) -> tuple[str, ...]:
    """The names of :func:`candidate_features`' vector without MC dropout (:data:`BASE_FEATURES` for UAVid)."""
    return CORE_FEATURES + context_features(labels)


CONTEXT_FEATURES: tuple[str, ...] = context_features(UAVID)  # the shipped model's (UAVid) names
BASE_FEATURES: tuple[str, ...] = CORE_FEATURES + CONTEXT_FEATURES
MCD_FEATURES: tuple[str, ...] = ("mcd_mean_std", "mcd_max_std")


# -- features ------------------------------------------------------------------------------------
def frame_window(shape: tuple[int, int], candidate: Any, scale: float, radii: float) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)``: a window of the working grid (h, w) holding every pixel of the candidate's disc of
    ``radii`` radii and the pixel under its centre (what :func:`frame_features` keeps for a tiny disc)."""
    h, w = shape
    cx, cy = candidate.x * scale, candidate.y * scale
    reach = candidate.radius_px * scale * radii + 1.0
    x0, y0 = min(max(int(cx - reach), 0), w - 1), min(max(int(cy - reach), 0), h - 1)
    x1, y1 = max(min(int(cx + reach) + 1, w), x0 + 1), max(min(int(cy + reach) + 1, h), y0 + 1)
    return x0, y0, x1, y1


def mcd_spread(samples: np.ndarray, disc_mask: np.ndarray, labels: LabelSet) -> list[float]:
    """Mean and largest standard deviation, over MC-dropout samples (n, C, h, w), of the disc's
    forbidden probability (:data:`MCD_FEATURES`)."""
    p = take_disc(samples, disc_mask).astype(np.float64)  # (n, 8, m)
    if p.shape[-1] == 0:
        return [0.0, 0.0]
    std = p[:, np.array(labels.forbidden_ids)].sum(axis=1).std(axis=0)
    return [float(std.mean()), float(std.max())]


def disc_summary(forbidden: list[np.ndarray], top_forbidden: np.ndarray, top_safe: np.ndarray
                 ) -> tuple[list[float], list[float]]:
    """A disc's four statistics (largest and mean forbidden probability, share of pixels a forbidden class wins, largest
    forbidden-over-safe margin) and each forbidden class's largest probability, from each forbidden class's scores on
    its m pixels and the pixels' top forbidden and top safe scores, (m,) each; the forbidden classes summed class
    after class in float64."""
    m = top_forbidden.shape[0]
    if m == 0:
        return [1.0, 1.0, 1.0, 1.0], [1.0] * len(forbidden)  # nothing seen: as bad as it gets
    forbidden_p = forbidden[0].astype(np.float64)
    for scores in forbidden[1:]:
        forbidden_p += scores  # class after class, as sum(axis=0) adds them
    margin = top_forbidden.astype(np.float64) - top_safe
    return ([float(forbidden_p.max()), float(forbidden_p.mean()),
             float(np.count_nonzero(top_forbidden >= top_safe) / m), float(margin.max())],
            [float(scores.max()) for scores in forbidden])


def patch_stats(patch_probs: np.ndarray, patch: Patch, candidate: Any, margin: float, labels: LabelSet
                ) -> tuple[list[float], float, list[float]]:
    """The HD disc's statistics (:func:`disc_summary` of the pixels ``take_disc(patch_probs, patch.disc_mask)``
    picks), the :func:`nearest_forbidden` edge distance and the HD disc's largest forbidden class probabilities, from
    one pass of the patch's top scores and the forbidden classes alone picked out of the disc."""
    top_forbidden, top_safe = top_scores(patch_probs, labels)
    edge = nearest_forbidden(top_forbidden >= top_safe, patch, candidate, margin)
    idx = np.flatnonzero(patch.disc_mask)  # the disc's pixels in raster order, as take_disc picks them
    forbidden = [np.ravel(patch_probs[c]).take(idx) for c in labels.forbidden_ids]
    stats, largest = disc_summary(forbidden, np.ravel(top_forbidden).take(idx), np.ravel(top_safe).take(idx))
    return stats, edge, largest


def nearest_forbidden(forbidden: np.ndarray, patch: Patch, candidate: Any, margin: float) -> float:
    """Distance from the disc's edge to the nearest forbidden pixel of the HD patch (``forbidden``, (h, w) bool), in
    radii: < 0 inside the disc (-1 at the centre), the patch's reach ``(1 + margin) sqrt(2) - 1`` when the patch holds
    none. Pixel centres are mapped back to full-resolution coordinates; the smallest squared distance is found row by
    row (the smallest x^2 of a row's forbidden pixels plus the row's y^2: rounding is monotonic, so it is the
    smallest of all)."""
    cap = (1.0 + margin) * math.sqrt(2.0) - 1.0
    h, w = forbidden.shape
    x = patch.offset[0] + (np.arange(w) + 0.5) / patch.scale - candidate.x
    y = patch.offset[1] + (np.arange(h) + 0.5) / patch.scale - candidate.y
    d2 = float((np.where(forbidden, x * x, np.inf).min(axis=1) + y * y).min())
    if d2 == math.inf:  # no forbidden pixel in the patch
        return cap
    return min(max(math.sqrt(d2) / candidate.radius_px - 1.0, -1.0), cap)


def frame_features(frame: np.ndarray, candidate: Any, scale: float, labels: LabelSet
                   ) -> tuple[list[float], list[float], list[float]]:
    """The frame disc's statistics (:func:`disc_summary`), the context statistics (largest and mean forbidden
    probability in discs of :data:`CONTEXT_SCALES` radii: the safe disc and what lies just beyond it) and the frame
    disc's largest forbidden class probabilities, on the working grid (``scale``: working pixels per full-resolution
    pixel). Every disc's pixels are picked from one grid of squared distances
    (``el.geometry.discs.window_sq_distances``, as
    ``disc_window_mask`` draws them; at least the pixel under the centre), the forbidden probability summed once over
    the context window."""
    h, w = frame.shape[1:]
    x0, y0, x1, y1 = frame_window((h, w), candidate, scale, max(CONTEXT_SCALES))  # holds every disc
    d2 = window_sq_distances(candidate.x * scale, candidate.y * scale, x0, y0, x1, y1)
    centre = (min(max(int(candidate.y * scale), 0), h - 1) - y0, min(max(int(candidate.x * scale), 0), w - 1) - x0)

    def disc(radii: float) -> np.ndarray:
        r = candidate.radius_px * scale * radii
        mask = d2 <= r * r
        if not mask.any():
            mask[centre] = True  # a disc smaller than a pixel: the pixel under its centre
        return mask

    ys, xs = np.nonzero(disc(1.0))
    pixels = frame[:, ys + y0, xs + x0]  # (C, m), raster order
    stats, largest = disc_summary([pixels[c] for c in labels.forbidden_ids], *top_scores(pixels, labels))
    first, *rest = labels.forbidden_ids
    window = frame[first, y0:y1, x0:x1].astype(np.float64)
    for c in rest:
        window += frame[c, y0:y1, x0:x1]  # class after class, in float64
    context: list[float] = []
    for k in CONTEXT_SCALES:
        forbidden_p = window[disc(k)]
        context += [float(forbidden_p.max()), float(forbidden_p.mean())]
    return stats, context, largest


def candidate_features(patch_probs: np.ndarray, patch: Patch, context: CandidateContext, *, margin: float,
                       mcd_samples: np.ndarray | None = None, labels: LabelSet) -> np.ndarray:
    """The feature vector of one candidate: :func:`base_features` (:data:`BASE_FEATURES` for UAVid), then
    :data:`MCD_FEATURES` with samples.

    ``patch_probs``: the HD patch's softmax (C, h, w) over ``labels``; ``context``: the candidate and the
    frame's softmax.
    """
    validate_scores(patch_probs, patch.shape, "patch softmax", labels=labels)
    frame = context.frame_probs
    if not isinstance(frame, np.ndarray) or frame.ndim != 3 or frame.shape[0] != patch_probs.shape[0]:
        raise ValueError(f"frame softmax must be ({labels.num_classes}, h, w), got {getattr(frame, 'shape', frame)!r}")
    if not context.frame_checked:
        validate_scores(frame, frame.shape[1:], "frame softmax", labels=labels)
    cand = context.candidate
    width, height = context.frame_size
    lr_stats, ctx_stats, lr_max = frame_features(frame, cand, frame.shape[2] / width, labels)
    hd_stats, edge, hd_max = patch_stats(patch_probs, patch, cand, margin, labels)
    values = [*lr_stats, *hd_stats, edge, cand.y / height, cand.radius_px / height, float(cand.hazard),
              *ctx_stats, *hd_max, *lr_max]
    if mcd_samples is not None:
        values += mcd_spread(mcd_samples, patch.disc_mask, labels)
    out = np.asarray(values, dtype=np.float64)
    if not np.isfinite(out).all():
        raise ValueError("non-finite candidate features")
    return out


# -- the model file --------------------------------------------------------------------------------
@dataclass(frozen=True)
class LearnedModel(HashedRecord):
    """A checked learned-monitor model (:func:`load_learned_model`): standardised logistic regression."""

    FORMAT: ClassVar[str] = MODEL_FORMAT
    WHAT: ClassVar[str] = "learned monitor model"
    ERROR: ClassVar[type[ValueError]] = LearnedModelError

    mean: np.ndarray
    scale: np.ndarray
    coef: np.ndarray
    intercept: float
    columns: np.ndarray  # where each of the model's features lies in the vector :func:`candidate_features` gives
    labels: LabelSet  # the label set whose features the model reads

    @property
    def features(self) -> tuple[str, ...]:
        return tuple(self.body["features"])

    @property
    def threshold(self) -> float:
        return float(self.body["threshold"])

    @property
    def width(self) -> int:
        """Length of the feature vector the monitor computes for this model (with MC dropout or not)."""
        return len(base_features(self.labels)) + (len(MCD_FEATURES) if self.mcd_n > 0 else 0)

    @property
    def mcd_n(self) -> int:
        return int(self.body.get("mcd", {}).get("n", 0))

    @property
    def mcd_rho(self) -> float:
        return float(self.body.get("mcd", {}).get("rho", 0.9))

    def predict(self, x: np.ndarray) -> np.ndarray:
        """P(truly unsafe) of rows ``x`` (n, D) or one row (D,) of :func:`candidate_features` vectors."""
        x = np.asarray(x, np.float64)
        if x.shape[-1] != self.width:
            raise ValueError(f"expected candidate feature vectors of {self.width} values, got {x.shape}")
        return logistic(((x[..., self.columns] - self.mean) / self.scale) * self.coef, self.intercept)


def logistic(terms: np.ndarray, intercept: float) -> np.ndarray:
    """``1 / (1 + exp(-(sum of terms + intercept)))`` over the last axis of ``terms``, in an arithmetic that gives the
    same bits on every x86-64 CPU (issue 60): the terms summed one column after the other (a matrix product's sum
    order is its BLAS kernel's, which OpenBLAS picks per CPU: 87 of 200 rows differed in their last bits between its
    AVX-512 and AVX2 kernels), and the exponential from the C library's ``exp`` (NumPy's own is another code on AVX-512
    CPUs: 4.5% of values differed). Returns float64 of the shape of ``terms`` less its last axis (a float for one
    row)."""
    terms = np.asarray(terms, dtype=np.float64)
    z = np.zeros(terms.shape[:-1], dtype=np.float64)
    for j in range(terms.shape[-1]):
        z += terms[..., j]
    z += intercept
    e = np.array([math.exp(-v) for v in np.clip(z, -500.0, 500.0).ravel()], dtype=np.float64).reshape(z.shape)
    return 1.0 / (1.0 + e)


def feature_columns(names: tuple[str, ...], mcd_n: int, labels: LabelSet) -> np.ndarray:
    """Positions of a model's feature names in the computed vector; any subset of this version's
    features, in any order (a model fitted before the context features were added keeps working)."""
    known = base_features(labels) + (MCD_FEATURES if mcd_n > 0 else ())
    if not names:
        raise ValueError("the feature list is empty")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"features listed twice: {twice}")
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"features {unknown} are not among this version's {list(known)}")
    return np.array([known.index(n) for n in names], dtype=np.int64)


def model_document(body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a model with this body (format and hash added)."""
    return LearnedModel.document(body)


def _vector(body: dict[str, Any], key: str, d: int) -> np.ndarray:
    v = np.asarray(body[key], dtype=np.float64)
    if v.shape != (d,) or not np.isfinite(v).all():
        raise ValueError(f"{key} must be {d} finite numbers")
    return v


def load_learned_model(path: str | Path | None = None, *, labels: LabelSet) -> LearnedModel:
    """Read and check a model file (default: the shipped ``el/monitors/data/learned.json``, fitted on
    UAVid), whose features are those of ``labels``.

    Raises
    ------
    LearnedModelError
        One line naming the file and the problem (missing, not JSON, altered, inconsistent).
    """
    p = Path(path) if path else DEFAULT_MODEL
    hint = " (train one with: uav-el fit-monitor --data data/train --val data/val --out FILE)"
    body, digest = LearnedModel.read_body(p, hint=hint)
    try:
        names = tuple(body["features"])
        mcd_n = int(body.get("mcd", {}).get("n", 0))
        columns = feature_columns(names, mcd_n, labels)
        d = len(names)
        mean, scale, coef = (_vector(body, k, d) for k in ("mean", "scale", "coef"))
        if (scale <= 0).any():
            raise ValueError("scale must be positive")
        intercept = float(body["intercept"])
        threshold = float(body["threshold"])
        if not (math.isfinite(intercept) and math.isfinite(threshold)):
            raise ValueError("intercept and threshold must be finite")
    except (KeyError, TypeError, ValueError) as exc:
        raise LearnedModelError(f"{p}: inconsistent learned monitor model ({exc})") from None
    return LearnedModel(str(p), digest, body, mean, scale, coef, intercept, columns, labels)


# -- the monitor -----------------------------------------------------------------------------------
class LearnedMonitor(LHDMonitor):
    """``learned[:model=FILE]``: P(truly unsafe) from a logistic regression on candidate features.

    Needs the candidate's :class:`CandidateContext` (the decision loop and the campaign give it). The
    default threshold is the model file's; the segmenter must be the one the model was trained on
    (:meth:`check_network`: its ``weights_sha256`` is the one the model file records).
    """

    PARAMS: ClassVar[dict[str, Any]] = {"model": str}
    SCORE_RANGE: ClassVar[tuple[float, float]] = (0.0, 1.0)  # a probability

    def __init__(self, *, labels: LabelSet, model: str | None = None, threshold: float | None = None,
                 **common: Any) -> None:
        self.model_path = model
        self.model = load_learned_model(model, labels=labels)
        self.DEFAULT_THRESHOLD = self.model.threshold  # type: ignore[misc]  # per model file, not per class
        super().__init__(threshold=threshold, labels=labels, **common)

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        return self.generic_spec("learned", model=self.model_path)

    @property
    def feature_key(self) -> Hashable:
        return ("learned", self.model.sha256, self.margin, self.max_side)

    @property
    def model_sha256(self) -> str:
        return self.model.sha256

    def patch_features(self, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0, size: int | None = None,
                       trunk: Any = None, context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        if context is None:
            raise ValueError("the learned monitor needs the candidate's context (frame softmax)")
        self.check_network(segmenter)
        probs, _ = super().patch_features(patch, segmenter, seed=seed, trunk=trunk)
        return self.softmax_features(probs, patch, segmenter, seed=seed, context=context)

    def softmax_features(self, probs: np.ndarray, patch: Patch, segmenter: PatchSegmenter, *, seed: int = 0,
                         context: CandidateContext | None = None) -> tuple[Any, np.ndarray]:
        """The candidate's feature vector from its patch's softmax (and its MC-dropout samples, when the model
        reads them)."""
        if context is None:
            raise ValueError("the learned monitor needs the candidate's context (frame softmax)")
        self.check_network(segmenter)
        samples = None
        if self.model.mcd_n > 0:
            samples = segmenter.mc_dropout(patch.rgb, self.model.mcd_n, self.model.mcd_rho, seed)
        return candidate_features(probs, patch, context, margin=self.margin, mcd_samples=samples,
                                  labels=self.labels), patch.disc_mask

    def check_network(self, segmenter: Any) -> None:
        """Refuse a network the model was not fitted on: the segmenter must report the weights hash the model
        file records (``weights.sha256``); a model fitted on an unidentified network needs an unidentified one."""
        self.model.check_network(segmenter)

    @property
    def reduce_key(self) -> Hashable:
        return ("learned_score", self.model.sha256)

    def reduce(self, features: Any, disc_mask: np.ndarray) -> float:
        x = np.asarray(features, dtype=np.float64)
        if x.shape != (self.model.width,) or not np.isfinite(x).all():
            raise ValueError(f"learned monitor: expected {self.model.width} finite features, got {x.shape}")
        return float(self.model.predict(x))

    def judge(self, reduced: Any) -> Judgement:
        score = float(reduced)
        accepted = self.accepts(score)
        return Judgement(score, accepted, f"P(unsafe) {score:.4f} {'<=' if accepted else '>'} "
                                          f"threshold {self.threshold:.4g}")

    def features(self, rgb_patch: np.ndarray, segmenter: PatchSegmenter, *, seed: int = 0) -> np.ndarray:
        raise ValueError("the learned monitor judges candidates in context (check(..., context=...))")
