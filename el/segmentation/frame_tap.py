"""What a frame's own forward pass computed, kept for the frame gates (``el.monitors.gates``): the gates read it
instead of running the network's trunk a second time.

``pooled``: per-channel mean and standard deviation over space of every trunk level (None when the network has
no trunk, or runs in ONNX Runtime from an export without trunk outputs: logits only); ``energy``: the mean
over pixels of ``-logsumexp`` of the frame logits on a 1-in-4 pixel grid (higher = less like the training
frames); ``msp``: the mean top softmax.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

GRID = 4  # energy and MSP on every 4th pixel in each direction: 16 times less work, the same mean to ~1e-3


@dataclass(frozen=True)
class FrameTap:
    """The statistics of one frame's forward pass (first image of the batch, scale 1, not flipped)."""

    energy: float
    msp: float
    pooled: np.ndarray | None = None


def trunk_levels(features: Any) -> list[Any]:
    """The trunk's feature maps (B, C, h, w): LiteSeg's ``levels``, MSDLite's ``deep`` and ``skip``, the ONNX
    export's trunk outputs (a list), or a tensor itself."""
    if hasattr(features, "levels"):
        return list(features.levels)
    if hasattr(features, "deep"):
        return [features.deep, features.skip]
    return list(features) if isinstance(features, list | tuple) else [features]


def frame_tap(logits: torch.Tensor, features: Any = None) -> FrameTap:
    """The tap of the first frame of a batch from its logits (B, C, H, W) and, when known, its trunk features:
    every level's per-channel mean and standard deviation over space, concatenated."""
    z = logits[0, :, ::GRID, ::GRID].float().cpu().numpy()  # a 1-in-4 grid: the logits are upsampled anyway
    top = z.max(axis=0)
    lse = top + np.log(np.exp(z - top).sum(axis=0))  # numpy: torch's logsumexp is far slower on these shapes
    msp = np.exp(top - lse)
    pooled = None
    if features is not None:
        parts = []
        for level in trunk_levels(features):  # numpy: several times faster than torch on these small maps
            a = level.detach().cpu().numpy() if isinstance(level, torch.Tensor) else np.asarray(level)
            flat = a[0].reshape(a.shape[1], -1).astype(np.float32, copy=False)
            parts += [flat.mean(axis=1), flat.std(axis=1)]
        pooled = np.concatenate(parts).astype(np.float64)
    return FrameTap(energy=float(-lse.mean()), msp=float(msp.mean()), pooled=pooled)
