"""The one check of an RGB image crossing an API: ndarray, shape (H, W, 3), uint8, big enough.

Used by the runtime monitors' patch extraction (any size), the segmenter (at least 16 px a side: the
network's stride needs it) and the perturbations (any size). The messages are the ones the decision
loop has always put in its reasons (``"image must be uint8, got float32"``, ``"image of 8x8 px is too
small"``), so a caller that adopts this check keeps its reason strings.
"""

from __future__ import annotations

import numpy as np


def check_rgb(image: object, what: str = "image", *, min_size: int = 1) -> np.ndarray:
    """Return ``image`` if it is an RGB uint8 ndarray of shape (H, W, 3) with H, W >= ``min_size``.

    Raises
    ------
    ValueError
        Naming ``what`` and the first problem found, checked in this order: not an ndarray, wrong
        shape, wrong dtype, too small.
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{what} must be a numpy array, got {type(image).__name__}")
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{what} must have shape (H, W, 3), got {image.shape}")
    if image.dtype != np.uint8:
        raise ValueError(f"{what} must be uint8, got {image.dtype}")
    if image.shape[0] < min_size or image.shape[1] < min_size:
        raise ValueError(f"{what} of {image.shape[1]}x{image.shape[0]} px is too small")
    return image
