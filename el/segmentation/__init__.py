"""Semantic segmentation: the model seam, the shipped networks, weights with model cards, inference.

Public entry points::

    from el.segmentation import load_model
    seg = load_model()                     # shipped weights, SHA-256 checked (or a .pt, or a plugin name)
    probs = seg.predict_frame(rgb)         # (C, h, w) softmax at working resolution

A user's own network plugs in through :class:`el.segmentation.contract.SegmentationModel`.

The names below are imported on first use (PEP 562): torch is an optional heavy dependency (the ``train`` extra),
and the deployed system runs the shipped network's ONNX export without it (:mod:`el.segmentation.onnx_segmenter`),
so importing this package must not import the torch modules.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "DEFAULT_WEIGHTS": "el.segmentation.weights",
    "MIN_SIZE": "el.segmentation.inference",
    "ArchConfig": "el.segmentation.model",
    "FrameOptions": "el.segmentation.protocol",
    "MSDLite": "el.segmentation.model",
    "SegmentationModel": "el.segmentation.contract",
    "Segmenter": "el.segmentation.inference",
    "WeightsError": "el.segmentation.weights",
    "build_model": "el.segmentation.architectures",
    "load_model": "el.segmentation.factory",
    "load_weights": "el.segmentation.weights",
}


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_WHERE[name]), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])


__all__ = [
    "DEFAULT_WEIGHTS",
    "MIN_SIZE",
    "ArchConfig",
    "FrameOptions",
    "MSDLite",
    "SegmentationModel",
    "Segmenter",
    "WeightsError",
    "build_model",
    "load_model",
    "load_weights",
]
