"""Semantic segmentation: the network, weights with model cards, inference, training.

Public entry points::

    from el.segmentation import Segmenter, WeightsError
    seg = Segmenter.load()                 # shipped weights, SHA-256 checked
    probs = seg.predict_frame(rgb)         # (8, h, w) softmax at working resolution
"""

from el.segmentation.architectures import build_model
from el.segmentation.inference import MIN_SIZE, Segmenter
from el.segmentation.model import ArchConfig, MSDLite
from el.segmentation.weights import DEFAULT_WEIGHTS, WeightsError, load_weights

__all__ = [
    "DEFAULT_WEIGHTS",
    "MIN_SIZE",
    "ArchConfig",
    "MSDLite",
    "Segmenter",
    "WeightsError",
    "build_model",
    "load_weights",
]
