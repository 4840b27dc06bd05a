"""``gmm``: the negative log-likelihood of a candidate's features under a Gaussian mixture of the safe ones.

A Gaussian mixture density of a network's features as a runtime monitor, as compared in the benchmark of
Guerin, Delmas, Ferreira & Guiochet, "Out-of-distribution detection is not all you need" (AAAI 2023) and its
successor benchmark of runtime monitors (UAI 2024); the mixture is fitted by expectation-maximisation
(Dempster, Laird & Rubin, 1977) on the truly safe training candidates' standardised features
(``assurance.fitting.detectors``: scikit-learn's ``GaussianMixture``, full covariances). Stored: the weights, means
and the Cholesky factors of the precisions (sklearn's ``precisions_cholesky_``); the score is numpy only.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from el.monitors.fitted import FittedDetectorMonitor


def gmm_score(z: np.ndarray, weights: np.ndarray, means: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """``-log p(z)`` of rows ``z`` (n, d) under the mixture (weights (k,), means (k, d), precision Cholesky
    factors (k, d, d), as sklearn's ``precisions_cholesky_`` with ``covariance_type="full"``).

    >>> import numpy as np     # one standard normal component in 1-D at z = 0: -log(1/sqrt(2 pi))
    >>> round(float(gmm_score(np.zeros((1, 1)), np.ones(1), np.zeros((1, 1)), np.ones((1, 1, 1)))[0]), 6)
    0.918939
    """
    z = np.asarray(z, np.float64)
    d = z.shape[1]
    y = np.einsum("nd,kde->nke", z, chol) - np.einsum("kd,kde->ke", means, chol)[None]
    log_det = np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
    log_p = np.log(weights)[None] + log_det[None] - 0.5 * (y * y).sum(axis=2) - 0.5 * d * math.log(2.0 * math.pi)
    top = log_p.max(axis=1, keepdims=True)
    return -(top[:, 0] + np.log(np.exp(log_p - top).sum(axis=1)))


class GMMMonitor(FittedDetectorMonitor):
    """``gmm:model=FILE``: -log-likelihood under a Gaussian mixture of the safe training candidates' features."""

    KIND = "gmm"
    SHAPES: ClassVar[dict[str, tuple[str, ...]]] = {"weights": ("k",), "means": ("k", "d"),
                                                    "precisions_cholesky": ("k", "d", "d")}

    def distance(self, z: np.ndarray) -> np.ndarray:
        p = self.record.params
        return gmm_score(z, p["weights"], p["means"], p["precisions_cholesky"])
