"""``doctor``: DOCTOR's misclassification detector on the worst disc pixel's softmax.

Granese, Romanelli, Gorla, Palamidessi & Piantanida, "DOCTOR: A simple method for detecting misclassification
errors", NeurIPS 2021. DOCTOR needs the softmax alone (a black-box detector): ``D_alpha`` scores an input by
``(1 - g) / g`` with ``g = sum_c p_c^2`` (the Gini impurity over the probability that two draws agree);
``D_beta`` by ``(1 - max_c p_c) / max_c p_c``. The per-pixel softmax of the segmentation pass is all it reads.

As the other softmax-family monitors (:mod:`el.monitors.softmax_scores`), the score is LHD's forbidden
branch (``1 + fraction`` > 1) or the largest per-pixel DOCTOR ratio in the disc, normalised by its largest
value (``C - 1`` for both variants, C the network's class count) into [0, 1].
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from el.monitors.softmax_scores import SoftmaxScoreMonitor
from el.monitors.spec import GenericSpec

VARIANTS = ("alpha", "beta")


class DOCTORMonitor(SoftmaxScoreMonitor):
    """``doctor[:variant=alpha|beta]``: DOCTOR's D_alpha (default) or D_beta (Granese et al., NeurIPS 2021).

    Examples
    --------
    >>> import numpy as np
    >>> from el.classes.labels import UAVID
    >>> p = np.array([[0.5], [0.5]])                         # g = 0.5: (1 - g) / g = 1 = C - 1 for C = 2
    >>> float(DOCTORMonitor(labels=UAVID, network_classes=2).uncertainty(p)[0])
    1.0
    """

    KIND = "doctor"
    PARAMS: ClassVar[dict[str, Any]] = {"variant": str}

    def __init__(self, *, variant: str = "alpha", network_classes: int | None = None, **kwargs: Any) -> None:
        if variant not in VARIANTS:
            raise ValueError(f"doctor: variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        self.variant = variant
        super().__init__(network_classes=network_classes, **kwargs)

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        return self.generic_spec(self.KIND, variant=None if self.variant == "alpha" else self.variant)

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        p = pixel_scores / np.maximum(pixel_scores.sum(axis=0, keepdims=True), 1e-12)
        g = (p * p).sum(axis=0) if self.variant == "alpha" else p.max(axis=0)
        ratio = (1.0 - g) / np.maximum(g, 1e-12)
        return self.capped(np.maximum(ratio, 0.0) / (self.classes - 1.0))
