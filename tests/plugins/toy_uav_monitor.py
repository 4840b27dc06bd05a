"""A toy runtime monitor, as a package outside uav-el-assurance would ship it (README: adding a monitor).

Score: the q-quantile over the disc's pixels of their forbidden probability mass; rejected above the
threshold (0.5 by default). It reads LHD's features (the HD softmax of the disc), so a campaign shares
them with LHD and CH.
"""

from __future__ import annotations

import numpy as np

from el.classes.labels import FORBIDDEN_IDS
from el.monitors.base import Judgement
from el.monitors.lhd import LHDMonitor


class ToyMonitor(LHDMonitor):
    PARAMS = {"q": float}  # spec parameters and their converters: toy:q=0.9
    DEFAULT_THRESHOLD = 0.5

    def __init__(self, *, q: float = 1.0, **common) -> None:
        super().__init__(**common)
        if not 0.0 <= q <= 1.0:
            raise ValueError(f"q must lie in [0, 1], got {q!r}")
        self.q = q

    @property
    def spec(self):
        return self.generic_spec("toy", q=self.q)

    def judge_pixels(self, pixel_scores, threshold=None):
        score = float(np.quantile(pixel_scores[list(FORBIDDEN_IDS)].sum(axis=0), self.q))
        accepted = self.accepts(score)
        return Judgement(score, accepted, f"forbidden mass {self.threshold_note(score, accepted)}")
