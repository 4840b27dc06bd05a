"""A patch's trunk computed on first use: what ``Segmenter.patch_trunk`` hands out when ONNX Runtime runs the
full passes (``el.segmentation.inference``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from el.segmentation.batching import unit_nchw
from el.segmentation.onnx_engine import unflatten_features


class LazyTrunk:
    """A patch's trunk on first use, kept: what ``patch_trunk`` hands out when ONNX Runtime runs the full passes.

    When the export carries the trunk (``engine.trunk_names``), one ONNX Runtime pass gives the patch's logits
    (:meth:`patch_logits`, for ``predict_patch``) and its trunk (:meth:`get`, for MC dropout's torch head);
    otherwise torch computes the trunk, and only if MC dropout asks."""

    def __init__(self, segmenter: Any, rgb_patch: np.ndarray) -> None:
        self.segmenter, self.rgb_patch, self.value, self.logits = segmenter, rgb_patch, None, None

    def _onnx_pass(self) -> None:
        seg = self.segmenter
        logits, trunk = seg.engine.with_trunk(unit_nchw([self.rgb_patch]))
        self.logits = torch.from_numpy(logits)
        if "_trunk_template" not in seg.__dict__:  # the trunk's output type and fields, from a tiny torch pass
            with torch.inference_mode():
                side = 2 * int(getattr(seg.model, "stride", 16))
                seg._trunk_template = seg.model.trunk(torch.zeros(1, 3, side, side, device=seg.device))
        self.value = unflatten_features(seg._trunk_template, seg.engine.trunk_names,
                                        [torch.from_numpy(t).to(seg.device) for t in trunk], self.rgb_patch.shape[:2])

    def patch_logits(self) -> torch.Tensor | None:
        """The patch's logits from the pass that gave its trunk (None when the export has no trunk outputs)."""
        if self.logits is None and self.segmenter.engine.trunk_names:
            self._onnx_pass()
        return self.logits

    def get(self) -> Any:
        if self.value is None:
            if self.segmenter.engine.trunk_names:
                self._onnx_pass()
            else:
                with torch.inference_mode():
                    self.value = self.segmenter.model.trunk(self.segmenter._to_tensor([self.rgb_patch]))
        return self.value


def resolve(features: Any) -> Any:
    return features.get() if isinstance(features, LazyTrunk) else features
