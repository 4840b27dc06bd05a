"""``odin``: ODIN's temperature-scaled maximum softmax probability of the worst disc pixel.

Liang, Li & Srikant, "Enhancing the reliability of out-of-distribution image detection in neural networks"
(ODIN), ICLR 2018. ODIN scores an input by ``max_c softmax(f(x~)/T)_c`` where ``f`` are the logits, ``T`` a
temperature (1000 in the paper) and ``x~`` the input nudged by ``eps`` along the gradient of that score.

The segmenter gives softmax ``p``, not logits; logits are ``log p`` plus a per-pixel constant, and a softmax
ignores a constant, so ``softmax(f/T) = p^(1/T) / sum_c p_c^(1/T)`` **exactly**: the temperature part is
computed from the segmentation pass's own output. The input perturbation needs the gradient of the network
with respect to its input, which the segmentation seam (``predict_patch`` returns probabilities, and an ONNX
network has no gradients at all) does not offer: ``eps`` other than 0 is refused with one line when the
monitor is built.

As the other softmax-family monitors (:mod:`el.monitors.softmax_scores`), the score is LHD's forbidden
branch (``1 + fraction`` > 1) or the uncertainty ``1 - max_c softmax(log p / T)_c`` normalised by its
largest value ``1 - 1/C`` (C the network's class count).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from el.monitors.capabilities import MonitorSupportError
from el.monitors.softmax_scores import SoftmaxScoreMonitor
from el.monitors.spec import GenericSpec


class ODINMonitor(SoftmaxScoreMonitor):
    """``odin[:temperature=1000]``: 1 - max temperature-scaled softmax (Liang et al., ICLR 2018); ``eps`` is refused.

    Examples
    --------
    >>> import numpy as np
    >>> from el.classes.labels import UAVID
    >>> p = np.array([[0.5], [0.5]])                       # two classes, an even split: most uncertain
    >>> float(ODINMonitor(labels=UAVID, network_classes=2, temperature=1.0).uncertainty(p)[0])
    1.0
    """

    KIND = "odin"
    PARAMS: ClassVar[dict[str, Any]] = {"temperature": float, "eps": float}

    def __init__(self, *, temperature: float = 1000.0, eps: float = 0.0, network_classes: int | None = None,
                 **kwargs: Any) -> None:
        if isinstance(temperature, bool) or not isinstance(temperature, int | float) \
                or not np.isfinite(temperature) or temperature <= 0:
            raise ValueError(f"odin: temperature must be a positive number, got {temperature!r}")
        if eps != 0:
            raise MonitorSupportError(
                f"monitor 'odin:eps={eps:g}' needs the gradient of the network with respect to its input; the "
                "segmentation seam gives probabilities only (and an ONNX network has no gradients): use odin "
                "without eps (temperature scaling only)")
        self.T = float(temperature)
        super().__init__(network_classes=network_classes, **kwargs)

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        return self.generic_spec(self.KIND, temperature=None if self.T == 1000.0 else self.T)

    def uncertainty(self, pixel_scores: np.ndarray) -> np.ndarray:
        p = pixel_scores / np.maximum(pixel_scores.sum(axis=0, keepdims=True), 1e-12)
        q = p ** (1.0 / self.T)  # softmax(log p / T) up to its sum; 0 stays 0 (a class nobody reaches)
        top = q.max(axis=0) / np.maximum(q.sum(axis=0), 1e-300)
        return self.capped(np.maximum(1.0 - top, 0.0) / (1.0 - 1.0 / self.classes))
