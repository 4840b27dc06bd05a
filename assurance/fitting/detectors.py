"""Fitting of the feature-space detectors (``el.monitors.mahalanobis``, ``gmm``, ``outside_box``) and their records.

Each is fitted on the truly safe candidates of a training split (their learned-monitor feature vectors, from
``assurance.fitting.learned_monitor.collect_candidates``: the campaign's truth and the flight code's features),
standardised; its default threshold is chosen on held-out candidates by a named criterion
(``assurance.analysis.criteria``; default ``tnr-at-recall``: the largest threshold rejecting >= 95% of the unsafe
held-out candidates), and the record says which (``criterion``). The record is JSON, hashed (``el.monitors.fitted``).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable
from typing import Any

import numpy as np

from assurance.analysis.criteria import candidate_threshold
from assurance.fitting.learned_monitor import CandidateSet
from el.classes.labels import LabelSet
from el.monitors.fitted import DetectorRecord
from el.monitors.gmm import gmm_score
from el.monitors.learned import base_features
from el.monitors.mahalanobis import mahalanobis_score
from el.monitors.outside_box import box_score

FAMILIES = ("mahalanobis", "gmm", "outside_box")
DEFAULT_COMPONENTS = {"gmm": 3, "outside_box": 4}


def _mahalanobis(z: np.ndarray, k: int) -> tuple[dict[str, Any], Callable[[np.ndarray], np.ndarray]]:
    from sklearn.covariance import LedoitWolf

    lw = LedoitWolf().fit(z)
    centre, precision = lw.location_, lw.precision_
    return ({"centre": centre.tolist(), "precision": precision.tolist()},
            lambda x: mahalanobis_score(x, centre, precision))


def _gmm(z: np.ndarray, k: int) -> tuple[dict[str, Any], Callable[[np.ndarray], np.ndarray]]:
    from sklearn.mixture import GaussianMixture

    k = max(1, min(k, z.shape[0] // max(2, z.shape[1])))  # no more components than the data can hold
    g = GaussianMixture(n_components=k, covariance_type="full", reg_covar=1e-3, random_state=0).fit(z)
    w, mu, chol = g.weights_, g.means_, g.precisions_cholesky_
    return ({"weights": w.tolist(), "means": mu.tolist(), "precisions_cholesky": chol.tolist()},
            lambda x: gmm_score(x, w, mu, chol))


def _boxes(z: np.ndarray, k: int) -> tuple[dict[str, Any], Callable[[np.ndarray], np.ndarray]]:
    from sklearn.cluster import KMeans

    k = max(1, min(k, z.shape[0]))
    lab = KMeans(n_clusters=k, n_init=10, random_state=0).fit_predict(z)
    used = [c for c in range(k) if (lab == c).any()]
    lo = np.array([z[lab == c].min(axis=0) for c in used])
    hi = np.array([z[lab == c].max(axis=0) for c in used])
    return {"lo": lo.tolist(), "hi": hi.tolist()}, lambda x: box_score(x, lo, hi)


_FIT = {"mahalanobis": _mahalanobis, "gmm": _gmm, "outside_box": _boxes}


def fit_detector_body(family: str, train: CandidateSet, val: CandidateSet, *, labels: LabelSet,
                      criterion: str = "tnr-at-recall", recall: float = 0.95, components: int | None = None,
                      weights: dict[str, Any] | None = None) -> dict[str, Any]:
    """The record body of ``family`` fitted on ``train``'s safe candidates, threshold by ``criterion`` on ``val``."""
    if family not in _FIT:
        raise ValueError(f"unknown detector family {family!r} (known: {', '.join(FAMILIES)})")
    safe = train.x[~train.y]
    if safe.shape[0] < 3:
        raise ValueError(f"{family}: {safe.shape[0]} truly safe training candidates; at least 3 are needed")
    mean = safe.mean(axis=0)
    scale = safe.std(axis=0)
    scale[scale < 1e-9] = 1.0  # a constant feature: left as it is (sklearn's StandardScaler does so)
    k = components or DEFAULT_COMPONENTS.get(family, 1)
    params, score = _FIT[family]((safe - mean) / scale, k)
    val_scores = score((val.x - mean) / scale)
    threshold, note = candidate_threshold(criterion, val_scores, val.y, recall=recall)
    return {
        "family": family, "features": list(base_features(labels)), "labels": labels.name,
        "mean": mean.tolist(), "scale": scale.tolist(), "components": len(params.get("weights", params.get("lo", [0]))),
        "params": params, "threshold": threshold,
        "criterion": {"name": criterion, "on": "held-out candidates", "note": note},
        "training": {"candidates": int(train.y.size), "safe_used": int(safe.shape[0]), "sha256": train.sha256,
                     "images": train.images},
        "held_out": {"candidates": int(val.y.size), "unsafe": int(val.y.sum()), "sha256": val.sha256,
                     "images": val.images},
        "weights": weights or {},
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }


def detector_document(body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a record body (format and hash added)."""
    return DetectorRecord.document(body)
