"""Energy gate: the mean over pixels of ``-logsumexp`` of the frame logits (Liu et al. 2020, per pixel, averaged).
Needs only the logits, so it works for every engine; nothing to fit."""

from __future__ import annotations

from typing import Any

import numpy as np

from el.monitors.gates.features import tap_vector

NAME = "energy"
FEATURES = ("energy",)


def embed(tap: Any, features: str = "energy") -> np.ndarray:
    """The frame's energy, (1,)."""
    return tap_vector(tap, features)


def fit(train: np.ndarray) -> dict[str, Any]:
    """Nothing to fit: the score is the energy itself (the training frames' median is kept for reference)."""
    return {"train_median": float(np.median(np.asarray(train, np.float64)[:, 0]))}


def score(params: dict[str, Any], x: np.ndarray) -> np.ndarray:
    return np.asarray(x, np.float64)[:, 0]
