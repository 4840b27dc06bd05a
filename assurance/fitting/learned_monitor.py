"""Training of the learned candidate monitor (``el.monitors.learned``): features, fit, selection, file.

Candidates are the core model's on the clean scenes of a split, with the campaign's truth: a candidate
is truly unsafe when its disc holds a forbidden ground-truth pixel (``assurance.campaign.truth.true_hazard``
= 1, as ``true_unsafe`` in readouts and the candidate audit). The features are the ones the flight
code computes (``el.monitors.learned.candidate_features``), so training and flight cannot drift. Everything is
in the label set the segmentation model outputs (``labels_of``: the system's, for a network behind a class
map): the label maps are read in its palette, its forbidden classes make a candidate unsafe and name the
per-class features, and the file records it (``labels``), as the flight code builds the monitor in it.

Selection on held-out data (``--val``, or else every 5th scene of the training split): the L2
strength ``C`` of a class-balanced logistic regression on standardised features with the best AUROC,
then the threshold at the calibration-free point where recall of the unsafe candidates is >= 0.95
(the largest threshold that rejects at least that share of the held-out unsafe candidates). The
regression is then refitted on the training part with that ``C``. Gradient boosting is left out: its
trees cannot be stored as a few JSON numbers as simply, and the features are few and monotone.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from assurance.campaign.truth import true_hazard
from assurance.dataio.layouts import iter_samples, located, read_sample_labels
from assurance.dataio.uavid import Sample, read_image
from assurance.fitting.network_identity import network_record
from assurance.paths import shown_path
from assurance.progress import progress as bar
from el.base.hashing import sha256_file
from el.classes.labels import LabelSet
from el.geometry.config import CoreConfig
from el.landing.core import run_core
from el.monitors.base import CandidateContext
from el.monitors.learned import MCD_FEATURES, base_features, candidate_features, model_document
from el.monitors.patches import extract_patch
from el.segmentation.contract import labels_of

DEFAULT_CS: tuple[float, ...] = (0.01, 0.1, 1.0, 10.0)


@dataclass(frozen=True, kw_only=True)
class FeatureSettings:
    """How candidates and their features are computed: the core model's configuration that proposes them (``core``;
    None: ``CoreConfig()``), the patch around each (``margin``, ``max_side``), the MC-dropout features (``mcd_n``
    samples, 0: none, at keep probability ``mcd_rho``) and the samples' ``seed`` (candidate k draws ``seed + k``)."""

    core: CoreConfig | None = None
    margin: float = 0.25
    max_side: int | None = None
    mcd_n: int = 0
    mcd_rho: float = 0.9
    seed: int = 0


@dataclass(frozen=True, kw_only=True)
class Selection:
    """How the model is chosen on the held-out candidates: the L2 strengths ``cs`` tried (the best held-out AUROC
    wins) and the ``recall`` of unsafe candidates its threshold keeps."""

    cs: Sequence[float] = DEFAULT_CS
    recall: float = 0.95

    def __post_init__(self) -> None:
        check_recall(self.recall)
        if not self.cs or not all(math.isfinite(c) and c > 0 for c in self.cs):
            raise ValueError(f"L2 strengths must be positive and finite, got {list(self.cs)}")


def check_recall(recall: float) -> None:
    """Refuse a recall of held-out unsafe candidates outside (0, 1) (NaN included): a threshold keeping all or none
    of them is no threshold."""
    if not 0.0 < recall < 1.0:
        raise ValueError(f"recall must lie in (0, 1), got {recall}")


@dataclass
class CandidateSet:
    """Feature rows of candidates, their truth (True = unsafe), their scene index, and the split's hash."""

    x: np.ndarray
    y: np.ndarray
    scene: np.ndarray
    sha256: str
    images: int


def split_sha256(samples: Sequence[Sample], root: str | Path, *, labels: bool = True) -> str:
    """SHA-256 over the relative paths and SHA-256 of every image (and label) file of a split."""
    return split_digest((Path(f).relative_to(root), sha256_file(f)) for s in samples
                        for f in ((s.image_path, s.label_path) if labels else (s.image_path,)))


def split_digest(files: Iterable[tuple[str | Path, str]]) -> str:
    """The SHA-256 of a split from its files' relative paths and SHA-256 (:func:`split_sha256`, and the report's data
    record from hashes it already has)."""
    h = hashlib.sha256()
    for rel, sha in files:
        h.update(f"{rel}:{sha}\n".encode())
    return h.hexdigest()


def collect_candidates(data: str | Path, segmenter: Any, *, features: FeatureSettings | None = None,
                       images: int | None = None, samples: Sequence[Sample] | None = None,
                       progress: bool = False, desc: str = "scenes") -> CandidateSet:
    """Features and truth of every candidate of the clean scenes of ``data`` (or of ``samples`` in it), computed as
    ``features`` says (None: :class:`FeatureSettings`' defaults); ``progress`` shows a bar (``desc``) on stderr."""
    features = features or FeatureSettings()
    core = features.core or CoreConfig()
    margin, max_side, mcd_n, mcd_rho, seed = (features.margin, features.max_side, features.mcd_n, features.mcd_rho,
                                              features.seed)
    if samples is None:
        samples = list(iter_samples(data, require_labels=True))[:images]
    if not samples:
        raise ValueError(f"{data}: no labelled scenes")
    rows, truth, scene = [], [], []
    labels = labels_of(segmenter)  # the network's classes: the data's palette and what is forbidden
    for i, s in enumerate(bar(samples, total=len(samples), desc=desc, enabled=progress)):
        rgb, ids = read_image(s.image_path), read_sample_labels(s, labels)
        if ids.shape != rgb.shape[:2]:
            raise ValueError(f"{s.label_path}: label size {ids.shape} differs from the image {rgb.shape[:2]}")
        probs = segmenter.predict_frame(rgb)
        size = (rgb.shape[1], rgb.shape[0])
        for k, cand in enumerate(run_core(probs, size, core, labels=labels).candidates):
            patch = extract_patch(rgb, cand, margin=margin, max_side=max_side)
            samples_mc = segmenter.mc_dropout(patch.rgb, mcd_n, mcd_rho, seed + k) if mcd_n > 0 else None
            rows.append(candidate_features(segmenter.predict_patch(patch.rgb), patch,
                                           CandidateContext(cand, probs, size), margin=margin,
                                           mcd_samples=samples_mc, labels=labels))
            truth.append(true_hazard(ids, cand.disc, labels=labels) >= 1.0)
            scene.append(i)
    d = len(base_features(labels)) + (len(MCD_FEATURES) if mcd_n > 0 else 0)
    return CandidateSet(np.asarray(rows, np.float64).reshape(-1, d), np.asarray(truth, bool),
                        np.asarray(scene, np.int64), split_sha256(samples, data), len(samples))


def recall_threshold(scores: np.ndarray, unsafe: np.ndarray, recall: float = 0.95) -> float:
    """The largest threshold (reject iff score > threshold) that rejects >= ``recall`` of the unsafe ones."""
    s = np.sort(np.asarray(scores, np.float64)[np.asarray(unsafe, bool)])
    if s.size == 0:
        raise ValueError("no truly unsafe candidate in the held-out data: cannot set a recall threshold")
    allowed = int(math.floor((1.0 - recall) * s.size + 1e-9))  # unsafe candidates that may be accepted
    return float(np.nextafter(s[allowed], -np.inf))


def _fit(x: np.ndarray, y: np.ndarray, c: float) -> tuple[Any, Any]:
    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    scaler = StandardScaler().fit(x)
    clf = LogisticRegression(C=c, class_weight="balanced", max_iter=5000).fit(scaler.transform(x), y)
    return scaler, clf


def _auroc(y: np.ndarray, p: np.ndarray) -> float | None:
    from sklearn.metrics import roc_auc_score

    return float(roc_auc_score(y, p)) if 0 < y.sum() < y.size else None


def fit_learned_body(train: CandidateSet, val: CandidateSet, *, selection: Selection | None = None,
                     features: FeatureSettings | None = None, weights: dict[str, Any] | None = None,
                     splits: dict[str, Any] | None = None, labels: LabelSet) -> dict[str, Any]:
    """The model body: ``C`` by held-out AUROC, the recall threshold on the held-out part (``selection``; None: its
    defaults), what it rests on; ``features``: how the candidates' features were computed (their MC-dropout part;
    None: none); ``labels``: the label set they were computed in (their per-class names)."""
    selection, features = selection or Selection(), features or FeatureSettings()
    cs, recall, mcd_n, mcd_rho = selection.cs, selection.recall, features.mcd_n, features.mcd_rho
    import sklearn

    for name, part in (("training", train), ("held-out", val)):
        if part.y.sum() == 0 or part.y.all():
            raise ValueError(f"the {name} candidates need both safe and unsafe ones "
                             f"({int(part.y.sum())} unsafe of {part.y.size})")
    trials = []
    for c in cs:
        scaler, clf = _fit(train.x, train.y, c)
        trials.append((_auroc(val.y, clf.predict_proba(scaler.transform(val.x))[:, 1]) or 0.0, -c, c))
    best_auc, _, best_c = max(trials)
    scaler, clf = _fit(train.x, train.y, best_c)
    p_val = clf.predict_proba(scaler.transform(val.x))[:, 1]
    threshold = recall_threshold(p_val, val.y, recall)
    rejected = p_val > threshold
    names = list(base_features(labels)) + (list(MCD_FEATURES) if mcd_n > 0 else [])
    return {
        "features": names, "model": "logistic regression (L2, class-balanced) on standardised features",
        "mean": [float(v) for v in scaler.mean_], "scale": [float(v) for v in scaler.scale_],
        "coef": [float(v) for v in clf.coef_[0]], "intercept": float(clf.intercept_[0]),
        "threshold": threshold, "C": float(best_c), "mcd": {"n": int(mcd_n), "rho": float(mcd_rho)},
        "criterion": {"name": "tnr-at-recall", "recall": recall, "on": "held-out candidates"},
        "selection": {"C_auroc": [{"C": c, "auroc": a} for a, _, c in trials], "recall_target": recall,
                      "held_out_auroc": best_auc,
                      "held_out_recall": float(rejected[val.y].mean()),
                      "held_out_safe_rejected": float(rejected[~val.y].mean()) if (~val.y).any() else None},
        "training": {"candidates": int(train.y.size), "unsafe": int(train.y.sum()), "images": train.images,
                     "sha256": train.sha256},
        "held_out": {"candidates": int(val.y.size), "unsafe": int(val.y.sum()), "images": val.images,
                     "sha256": val.sha256},
        "splits": splits or {}, "weights": weights or {}, "sklearn_version": sklearn.__version__,
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }


def fit_learned_monitor(data: str | Path, segmenter: Any, *, val: str | Path | None = None,
                        features: FeatureSettings | None = None, selection: Selection | None = None,
                        images: int | None = None, weights: dict[str, Any] | None = None,
                        progress: bool = False) -> dict[str, Any]:
    """Train on the candidates of ``data``, select on ``val`` (else every 5th scene of ``data``): the JSON document.

    ``features``: how the candidates' features are computed (:class:`FeatureSettings`); ``selection``: how ``C`` and
    the threshold are chosen (:class:`Selection`); None: their defaults. ``weights``: the network record (default: the
    one ``segmenter`` reports; ValueError if it reports none)."""
    features = features or FeatureSettings()
    weights = weights if weights is not None else network_record(segmenter, loaded=False)
    kw = {"features": features, "progress": progress}
    scenes = list(iter_samples(data, require_labels=True))[:images]
    if val is None:
        held = scenes[4::5]
        if not held:
            raise ValueError(f"{data}: too few scenes to hold out every 5th (give --val)")
        train = collect_candidates(data, segmenter, samples=[s for i, s in enumerate(scenes) if i % 5 != 4],
                                   desc="training scenes", **kw)
        held_out = collect_candidates(data, segmenter, samples=held, desc="held-out scenes", **kw)
        splits = {"train": shown_path(data), "held_out": f"every 5th scene of {shown_path(data)}",
                  "spec": {"train": located(data), "held_out": located(data)}}
    else:
        train = collect_candidates(data, segmenter, samples=scenes, desc="training scenes", **kw)
        held_out = collect_candidates(val, segmenter, images=images, desc="held-out scenes", **kw)
        splits = {"train": shown_path(data), "held_out": shown_path(val),
                  "spec": {"train": located(data), "held_out": located(val)}}
    labels = labels_of(segmenter)
    body = fit_learned_body(train, held_out, selection=selection, features=features, weights=weights, splits=splits,
                            labels=labels)
    body["labels"] = labels.name  # the label set whose classes the features read (the flight code builds it so)
    body["patch"] = {"margin": features.margin, "max_side": features.max_side}
    return model_document(body)
