"""A frame's softmax at the working resolution, from a network's passes: what :class:`Segmenter` and the torch-free
:class:`~el.segmentation.onnx_segmenter.OnnxSegmenter` share (a mixin, no torch), so the shipped network segments a
frame by the same steps whichever runs it: resized (``cv2.INTER_AREA``) to :func:`el.camera.working_size`, each of
``frame_scales`` (mean), each with its mirror image when ``frame_flip``, brought back by ``frame_pooling``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from el.camera import working_size
from el.deadline import checkpoint
from el.rgb import check_rgb
from el.segmentation.pooling import downsample_probs

MIN_SIZE = 16  # smallest patch side (px) a segmenter accepts


def check_frame_rgb(rgb: Any, what: str) -> np.ndarray:
    return check_rgb(rgb, what, min_size=MIN_SIZE)


def check_finite(probs: np.ndarray, what: str) -> np.ndarray:
    # One summing pass: NaN and inf propagate through a sum of values in [0, 1] (or NaN/inf).
    if not np.isfinite(probs.sum(dtype=np.float64)):
        bad = int((~np.isfinite(probs)).sum())
        raise ValueError(f"{what}: segmentation output has {bad} non-finite values (NaN or inf)")
    return probs


class FramePasses:
    """:meth:`predict_frame` from the segmenter's ``_predict(images, what)`` (a batch's softmax, (B, C, h, w))."""

    last_tap: Any = None
    if TYPE_CHECKING:  # what the segmenter provides
        working_width: int
        frame_flip: bool
        frame_scales: tuple[float, ...]
        frame_pooling: str
        labels: Any

        def _predict(self, images: list[np.ndarray], what: str) -> np.ndarray: ...

    def working_size(self, width: int, height: int) -> tuple[int, int]:
        """(width, height) of the working resolution for a frame of the given size."""
        return working_size(width, height, self.working_width)

    def predict_frame(self, rgb: np.ndarray) -> np.ndarray:
        """Softmax of a frame at the working resolution.

        Parameters
        ----------
        rgb : ndarray of shape (H, W, 3), uint8
            The full-resolution frame.

        Returns
        -------
        ndarray of shape (8, h, w), float32, with ``(w, h) = working_size(W, H)``.
        """
        check_frame_rgb(rgb, "frame")
        self.last_tap = None  # FrameTap of this frame's first pass (el.segmentation.frame_tap)
        w, h = self.working_size(rgb.shape[1], rgb.shape[0])
        if (rgb.shape[1], rgb.shape[0]) != (w, h):
            rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
        check_frame_rgb(rgb, "frame at working resolution")
        total = None
        for scale in self.frame_scales:
            checkpoint("segmentation")  # the decision's deadline, between the network's passes
            probs = self._frame_at_scale(rgb, scale)
            total = probs if total is None else total + probs
        if len(self.frame_scales) > 1:
            total /= np.float32(len(self.frame_scales))
        return total

    def _frame_at_scale(self, rgb: np.ndarray, scale: float) -> np.ndarray:
        """Softmax (8, h, w) of a working-resolution frame fed to the network resized by ``scale``."""
        h, w = rgb.shape[:2]
        size = (max(MIN_SIZE, round(w * scale)), max(MIN_SIZE, round(h * scale)))
        view = rgb if size == (w, h) else cv2.resize(rgb, size, interpolation=cv2.INTER_LINEAR)
        if not self.frame_flip:
            probs = self._predict([view], "frame")[0]
        else:
            pair = self._predict([view, np.ascontiguousarray(view[:, ::-1])], "frame")
            probs = 0.5 * (pair[0] + pair[1][:, :, ::-1])
        if size != (w, h):  # back to the working resolution, over each pixel's footprint
            probs = downsample_probs(probs, (w, h), self.frame_pooling, labels=self.labels)
        return np.ascontiguousarray(probs, dtype=np.float32)
