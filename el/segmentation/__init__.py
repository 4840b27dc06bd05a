"""Semantic segmentation: the model seam, the shipped networks, weights with model cards, inference.

Public entry points::

    from el.segmentation import load_model
    seg = load_model()                     # shipped weights, SHA-256 checked (or a .pt, or a plugin name)
    probs = seg.predict_frame(rgb)         # (C, h, w) softmax at working resolution

A user's own network plugs in through :class:`el.segmentation.contract.SegmentationModel`.
"""

from el.segmentation.architectures import build_model
from el.segmentation.contract import SegmentationModel
from el.segmentation.factory import load_model
from el.segmentation.inference import MIN_SIZE, Segmenter
from el.segmentation.model import ArchConfig, MSDLite
from el.segmentation.weights import DEFAULT_WEIGHTS, WeightsError, load_weights

__all__ = [
    "DEFAULT_WEIGHTS",
    "MIN_SIZE",
    "ArchConfig",
    "MSDLite",
    "SegmentationModel",
    "Segmenter",
    "WeightsError",
    "build_model",
    "load_model",
    "load_weights",
]
