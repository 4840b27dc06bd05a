"""Reading a camera frame from a file as RGB uint8 (H, W, 3); OpenCV's BGR order stays inside this module.

The one file reader of the flight path: every error is a ``DataError`` naming the file and the problem,
which the decision loop turns into the default action.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from el.errors import DataError


def read_image(path: str | Path) -> np.ndarray:
    """Read a colour image as RGB uint8 (H, W, 3); DataError if missing, not an image or truncated."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such file")
    if not path.is_file():
        raise DataError(f"{path}: not a file")
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise DataError(f"{path}: empty file")
    if path.suffix.lower() == ".png" and not _png_complete(data):
        raise DataError(f"{path}: truncated or corrupt PNG (no IEND chunk)")
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DataError(f"{path}: not a readable image")
    if img.dtype != np.uint8:
        raise DataError(f"{path}: expected 8-bit image, got {img.dtype}")
    if img.ndim == 2:
        raise DataError(f"{path}: expected a colour (RGB) image, got a single-channel image")
    if img.shape[2] == 4:
        img = img[:, :, :3]
    elif img.shape[2] != 3:
        raise DataError(f"{path}: expected 3 colour channels, got {img.shape[2]}")
    return np.ascontiguousarray(img[:, :, ::-1])


def _png_complete(data: np.ndarray) -> bool:
    """A PNG whose last chunk is IEND: catches files cut short, which decoders may half-read."""
    return data.size >= 20 and bytes(data[-12:-4]) == b"\x00\x00\x00\x00IEND"
