"""Mahalanobis gate on the pooled trunk levels (per-channel mean and std of every level): the distance to the
training frames' mean under their shrunk covariance (fitted with Ledoit-Wolf shrinkage, computed here in numpy)."""

from __future__ import annotations

from typing import Any

import numpy as np

NAME = "mahalanobis"
NEEDS_TRUNK = True


def embed(tap: Any) -> np.ndarray:
    if tap.pooled is None:
        raise ValueError("the mahalanobis gate needs the trunk's features; this engine gives the logits only")
    return np.asarray(tap.pooled, np.float64)


def fit(train: np.ndarray) -> dict[str, Any]:
    """Mean and Ledoit-Wolf-shrunk precision of ``train`` (n, d), features standardised first."""
    x = np.asarray(train, np.float64)
    mu, sd = x.mean(axis=0), x.std(axis=0) + 1e-6
    z = (x - mu) / sd
    n, d = z.shape
    s = z.T @ z / n
    m = np.trace(s) / d
    d2 = np.sum((s - m * np.eye(d)) ** 2)
    b2 = min(d2, sum(np.sum((np.outer(r, r) - s) ** 2) for r in z) / n ** 2)
    shrink = 0.0 if d2 == 0 else b2 / d2
    cov = shrink * m * np.eye(d) + (1 - shrink) * s
    return {"mean": mu.tolist(), "scale": sd.tolist(), "precision": np.linalg.pinv(cov).tolist(),
            "shrinkage": float(shrink)}


def score(params: dict[str, Any], x: np.ndarray) -> np.ndarray:
    z = (np.asarray(x, np.float64) - np.asarray(params["mean"])) / np.asarray(params["scale"])
    p = np.asarray(params["precision"])
    return np.sqrt(np.maximum(np.einsum("nd,de,ne->n", z, p, z), 0.0))
