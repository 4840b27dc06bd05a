"""k-nearest-neighbour gate (Sun et al. 2022): the distance of the frame's L2-normalised pooled trunk features
(standardised by the training frames first) to its k-th nearest training frame."""

from __future__ import annotations

from typing import Any

import numpy as np

from el.monitors.gates.features import tap_vector

NAME = "knn"
FEATURES = ("pooled", "output")  # the trunk's statistics, else the output's
K = 5


def embed(tap: Any, features: str = "pooled") -> np.ndarray:
    """The frame's pooled statistics: its trunk's (``pooled``) or its output's (``output``), (d,)."""
    return tap_vector(tap, features)


def _normalised(params: dict[str, Any], x: np.ndarray) -> np.ndarray:
    z = (np.asarray(x, np.float64) - np.asarray(params["mean"])) / np.asarray(params["scale"])
    return z / np.maximum(np.linalg.norm(z, axis=1, keepdims=True), 1e-12)


def fit(train: np.ndarray) -> dict[str, Any]:
    """The training bank: standardisation and the normalised training embeddings."""
    x = np.asarray(train, np.float64)
    params: dict[str, Any] = {"mean": x.mean(axis=0).tolist(), "scale": (x.std(axis=0) + 1e-6).tolist(),
                              "k": min(K, len(x))}
    params["bank"] = _normalised(params, x).tolist()
    return params


def score(params: dict[str, Any], x: np.ndarray) -> np.ndarray:
    z, bank = _normalised(params, x), np.asarray(params["bank"])
    d = np.sqrt(np.maximum(2.0 - 2.0 * z @ bank.T, 0.0))
    return np.sort(d, axis=1)[:, int(params["k"]) - 1]
