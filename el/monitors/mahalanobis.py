"""``mahalanobis``: the Mahalanobis distance of a candidate's features to the safe training candidates.

Lee, Lee, Lee & Shin, "A simple unified framework for detecting out-of-distribution samples and adversarial
attacks", NeurIPS 2018: a Gaussian with a shared covariance is fitted to a network's features, and an input scores
its Mahalanobis distance to the nearest class mean. Here there is one class, the truly safe training candidates
(what a landing monitor should accept), in the candidate-feature space of :mod:`el.monitors.fitted`; the
covariance is the Ledoit-Wolf shrinkage estimate (fitted by ``assurance.fitting.detectors``), stored as its
inverse. Score: ``(z - mu)^T P (z - mu)`` on standardised features ``z``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from el.monitors.fitted import FittedDetectorMonitor


def mahalanobis_score(z: np.ndarray, centre: np.ndarray, precision: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distance of rows ``z`` (n, d) to ``centre`` (d,) under ``precision`` (d, d).

    >>> import numpy as np
    >>> float(mahalanobis_score(np.array([[1.0, 2.0]]), np.zeros(2), np.diag([1.0, 0.25]))[0])  # 1 + 4/4
    2.0
    """
    diff = np.asarray(z, np.float64) - centre
    return np.einsum("nd,de,ne->n", diff, precision, diff)


class MahalanobisMonitor(FittedDetectorMonitor):
    """``mahalanobis:model=FILE``: squared Mahalanobis distance to the safe training candidates (Lee et al., 2018)."""

    KIND = "mahalanobis"
    SHAPES: ClassVar[dict[str, tuple[str, ...]]] = {"centre": ("d",), "precision": ("d", "d")}

    def distance(self, z: np.ndarray) -> np.ndarray:
        return mahalanobis_score(z, self.record.params["centre"], self.record.params["precision"])
