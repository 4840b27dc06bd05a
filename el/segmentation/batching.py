"""Several HD patches through the network in few passes, with the scores each patch gets alone.

A candidate monitor segments one HD patch per candidate, and patches differ in size (a candidate's radius
follows its row). A network that pads its input by edge replication to a multiple of its stride (the
shipped :class:`~el.segmentation.model.TrunkHeadNet` networks and their ONNX exports: ``padded_input``)
computes a patch's scores on that padded image and crops them back. Padding the patch in the same way
before the pass feeds the network the very same image, so patches whose padded sizes agree can share one
batch, each cropped back to its own size afterwards (the ONNX export gives bit-identical logits; a torch
batch may differ from single passes in the last float bits). Networks that do not declare such padding are
batched only with patches of exactly their size (:func:`padding_multiple` is 1).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

Size = tuple[int, int]


def padding_multiple(model: Any) -> int:
    """The multiple a network edge-pads its input to (its ``stride``, for networks with ``padded_input``), else 1.

    Only networks that do it themselves qualify: padding a patch for any other network would change its scores.
    """
    stride = getattr(model, "stride", None)
    if not callable(getattr(model, "padded_input", None)) or isinstance(stride, bool) or not isinstance(stride, int):
        return 1
    return max(1, stride)


def padded_size(shape: Size, multiple: int) -> Size:
    """(H, W) of a patch of ``shape`` (h, w) edge-padded up to multiples of ``multiple``."""
    h, w = shape
    return -(-h // multiple) * multiple, -(-w // multiple) * multiple


def group_by_padded_size(shapes: Sequence[Size], multiple: int) -> dict[Size, list[int]]:
    """Indices of the patches of each padded size, in the order given (a dict keeps first-seen order)."""
    groups: dict[Size, list[int]] = {}
    for i, shape in enumerate(shapes):
        groups.setdefault(padded_size(shape, multiple), []).append(i)
    return groups


def pad_edge(rgb: np.ndarray, size: Size) -> np.ndarray:
    """``rgb`` (h, w, 3) edge-padded at the bottom and right to ``size`` (H, W): what the network does itself."""
    h, w = rgb.shape[:2]
    if (h, w) == tuple(size):
        return rgb
    return np.pad(rgb, ((0, size[0] - h), (0, size[1] - w), (0, 0)), mode="edge")


def padded_batch(patches: Sequence[np.ndarray], idx: Sequence[int], size: Size) -> list[np.ndarray]:
    """The patches ``idx`` edge-padded to ``size``: one batch of the network."""
    return [pad_edge(patches[i], size) for i in idx]


def unit_nchw(images: Sequence[np.ndarray]) -> np.ndarray:
    """RGB uint8 images (h, w, 3) of one size as the network's input batch: float32 (B, 3, h, w), C-contiguous,
    values ``v / 255`` (the same numbers as ``np.stack(images).astype(np.float32) / 255``, in one pass)."""
    h, w = images[0].shape[:2]
    out = np.empty((len(images), 3, h, w), np.float32)
    for i, rgb in enumerate(images):
        np.divide(rgb.transpose(2, 0, 1), np.float32(255.0), out=out[i], dtype=np.float32)
    return out
