"""Mahalanobis gate on the pooled trunk levels (per-channel mean and std of every level): the distance to the
training frames' mean under their covariance, shrunk towards its mean variance (a fixed ``SHRINKAGE``, or
Ledoit-Wolf's with ``shrinkage=None``), computed in numpy.

The distance is kept exactly along the ``COMPONENTS`` directions of largest training variance; the remaining
directions share their mean (shrunk) variance, so a fitted gate is d x k numbers, not d x d (the shipped file stays
small). ``COMPONENTS``, ``SHRINKAGE`` and the threshold quantile were chosen on validation scenes (docs/results.md)."""

from __future__ import annotations

from typing import Any

import numpy as np

from el.monitors.gates.features import tap_vector

NAME = "mahalanobis"
FEATURES = ("pooled", "output")  # the trunk's statistics, else the output's
SHRINKAGE = 0.1
COMPONENTS = 64


def embed(tap: Any, features: str = "pooled") -> np.ndarray:
    """The frame's pooled statistics: its trunk's (``pooled``) or its output's (``output``), (d,)."""
    return tap_vector(tap, features)


def ledoit_wolf(z: np.ndarray, s: np.ndarray) -> float:
    """Ledoit-Wolf's shrinkage intensity of the covariance ``s`` of standardised frames ``z`` (n, d)."""
    n, d = z.shape
    m = np.trace(s) / d
    d2 = np.sum((s - m * np.eye(d)) ** 2)
    b2 = min(d2, sum(np.sum((np.outer(r, r) - s) ** 2) for r in z) / n ** 2)
    return 0.0 if d2 == 0 else float(b2 / d2)


def fit(train: np.ndarray, shrinkage: float | None = SHRINKAGE, components: int = COMPONENTS) -> dict[str, Any]:
    """Mean, scale, the ``components`` leading directions of ``train`` (n, d) (features standardised first) and
    the shrunk variance along each, and the mean shrunk variance of the other directions."""
    x = np.asarray(train, np.float64)
    mu, sd = x.mean(axis=0), x.std(axis=0) + 1e-6
    z = (x - mu) / sd
    n, d = z.shape
    s = z.T @ z / n
    a = ledoit_wolf(z, s) if shrinkage is None else float(shrinkage)
    lam, vec = np.linalg.eigh(s)
    lam, vec = np.maximum(lam[::-1], 0.0), vec[:, ::-1]
    var = (1 - a) * lam + a * np.trace(s) / d
    k = min(int(components), d)
    rest = float(var[k:].mean()) if k < d else 1.0
    return {"mean": mu.tolist(), "scale": sd.tolist(), "basis": vec[:, :k].tolist(), "variance": var[:k].tolist(),
            "rest_variance": rest, "shrinkage": a}


def score(params: dict[str, Any], x: np.ndarray) -> np.ndarray:
    z = (np.asarray(x, np.float64) - np.asarray(params["mean"])) / np.asarray(params["scale"])
    p = z @ np.asarray(params["basis"])
    rest = np.maximum((z * z).sum(axis=1) - (p * p).sum(axis=1), 0.0)
    return np.sqrt((p * p / np.asarray(params["variance"])).sum(axis=1) + rest / float(params["rest_variance"]))
