"""``outside_box``: Outside-the-Box, the box abstraction of the safe candidates' features.

Henzinger, Lukina & Schilling, "Outside the Box: Abstraction-Based Monitoring of Neural Networks", ECAI 2020:
the features of the training inputs are clustered (k-means) and each cluster is abstracted by its bounding box
(enlarged by a factor); an input outside every box is flagged. Here the clusters are those of the truly safe
training candidates' standardised features (:mod:`el.monitors.fitted`; fitted by ``assurance.fitting.detectors``).

The paper's verdict is binary; the score makes it graded: for each box, the largest excess of a feature
beyond the box along any dimension, in box widths (0 inside the box); the score is the smallest over the
boxes. Threshold 0 is the paper's monitor exactly (reject iff outside every box); the record's threshold
(chosen when fitted) may tolerate some excess.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from el.monitors.fitted import FittedDetectorMonitor


def box_score(z: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Smallest (over boxes ``lo``, ``hi`` (k, d)) largest excess beyond the box in box widths, of rows ``z``.

    >>> import numpy as np         # box [0, 1] x [0, 2]: the point (1.5, 1) lies half a width beyond it
    >>> float(box_score(np.array([[1.5, 1.0]]), np.array([[0.0, 0.0]]), np.array([[1.0, 2.0]]))[0])
    0.5
    """
    z = np.asarray(z, np.float64)[:, None, :]
    width = np.maximum(hi - lo, 1e-9)[None]
    excess = np.maximum(np.maximum(lo[None] - z, z - hi[None]), 0.0) / width
    return excess.max(axis=2).min(axis=1)


class OutsideBoxMonitor(FittedDetectorMonitor):
    """``outside_box:model=FILE``: box-abstraction monitor (Henzinger, Lukina & Schilling, ECAI 2020), graded."""

    KIND = "outside_box"
    SHAPES: ClassVar[dict[str, tuple[str, ...]]] = {"lo": ("k", "d"), "hi": ("k", "d")}

    def distance(self, z: np.ndarray) -> np.ndarray:
        return box_score(z, self.record.params["lo"], self.record.params["hi"])
