"""What a frame's own forward pass computed, returned with its probabilities for the frame gates
(``el.monitors.gates``): the gates read it instead of running the network a second time.
``predict_frame(rgb, stats=True)`` returns a :class:`FramePass`, the probabilities and these statistics of the same
pass; nothing is kept on the model between calls.

``pooled``: per-channel mean and standard deviation over space of every trunk level (None when the network has
no trunk, or runs in ONNX Runtime from a file without trunk outputs); ``output``: per-class mean and standard
deviation over space of the frame's logits (every network has them: an ONNX file's output, or the log of its
probabilities when it gives probabilities), so a gate can be fitted on any network; ``energy``: the mean over
pixels of ``-logsumexp`` of the frame logits (higher = less like the training frames); ``msp``: the mean top
softmax. Energy, MSP and the output statistics are read on a 1-in-4 pixel grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

GRID = 4  # energy, MSP and output statistics on every 4th pixel in each direction: 16 times less work
TAP_FEATURES = ("pooled", "output")
"""The pooled feature vectors a tap may hold: the trunk's (``pooled``) and the output's (``output``)."""


@dataclass(frozen=True)
class FrameTap:
    """The statistics of one frame's forward pass (first image of the batch, scale 1, not flipped)."""

    energy: float
    msp: float
    pooled: np.ndarray | None = None
    output: np.ndarray | None = None


class FramePass(NamedTuple):
    """A frame's probabilities (C, h, w) and the statistics of the pass that computed them (``predict_frame(rgb,
    stats=True)``); ``stats`` None: the model returned none, so a frame gate cannot score the frame."""

    probs: np.ndarray
    stats: FrameTap | None


def trunk_levels(features: Any) -> list[Any]:
    """The trunk's feature maps (B, C, h, w): LiteSeg's ``levels``, MSDLite's ``deep`` and ``skip``, the ONNX
    export's trunk outputs (a list), or a tensor itself."""
    if hasattr(features, "levels"):
        return list(features.levels)
    if hasattr(features, "deep"):
        return [features.deep, features.skip]
    return list(features) if isinstance(features, list | tuple) else [features]


def _numpy(a: Any) -> np.ndarray:
    """A torch tensor or array-like as a numpy array (torch is not imported for an ONNX network's arrays)."""
    if hasattr(a, "detach"):
        return a.detach().float().cpu().numpy()  # type: ignore[no-any-return]
    return np.asarray(a)


def _mean_std(a: np.ndarray) -> list[np.ndarray]:
    """Per-channel mean and standard deviation over space of a (C, h, w) map."""
    flat = a.reshape(a.shape[0], -1).astype(np.float32, copy=False)
    return [flat.mean(axis=1), flat.std(axis=1)]


def frame_tap(logits: Any, features: Any = None, *, probabilities: bool = False) -> FrameTap:
    """The tap of the first frame of a batch from its logits (B, C, H, W; a torch tensor or a numpy array) and, when
    known, its trunk features (every level's per-channel mean and standard deviation over space, concatenated).

    ``probabilities``: ``logits`` are class probabilities (an ONNX file declaring ``output = probabilities``); their
    logarithm stands in for the logits (equal up to a per-pixel constant: the output statistics keep their meaning,
    the energy is then 0 for every frame)."""
    z = _numpy(logits[0, :, ::GRID, ::GRID]).astype(np.float32, copy=False)  # the logits are upsampled anyway
    if probabilities:
        z = np.log(np.maximum(z, np.float32(1e-12)))
    top = z.max(axis=0)
    lse = top + np.log(np.exp(z - top).sum(axis=0))  # numpy: torch's logsumexp is far slower on these shapes
    msp = np.exp(top - lse)
    pooled = None
    if features is not None:
        parts = []
        for level in trunk_levels(features):  # numpy: several times faster than torch on these small maps
            parts += _mean_std(_numpy(level)[0])
        pooled = np.concatenate(parts).astype(np.float64)
    output = np.concatenate(_mean_std(z)).astype(np.float64)
    return FrameTap(energy=float(-lse.mean()), msp=float(msp.mean()), pooled=pooled, output=output)
