"""A frame's softmax at the working resolution, from a network's passes: what :class:`Segmenter` and the torch-free
:class:`~el.segmentation.onnx_segmenter.OnnxSegmenter` share (a mixin, no torch), so the shipped network segments a
frame by the same steps whichever runs it: resized (``cv2.INTER_AREA``) to :func:`el.geometry.camera.working_size`,
each of
``frame_scales`` (mean), each with its mirror image when ``frame_flip``, brought back by ``frame_pooling``. Asked
for ``stats``, it returns the statistics of its first pass with the probabilities (``el.segmentation.frame_tap``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from el.base.deadline import checkpoint
from el.base.rgb import check_rgb
from el.geometry.camera import working_size
from el.segmentation.frame_tap import FramePass, FrameTap
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
    """:meth:`predict_frame` from the segmenter's ``_frame_pass(images, stats)`` (a batch's softmax, (B, C, h, w), and
    with ``stats`` the :class:`~el.segmentation.frame_tap.FrameTap` of its first image, else None)."""

    frame_stats = True  # el.segmentation.contract.FRAME_STATS: predict_frame(rgb, stats=True) -> FramePass
    if TYPE_CHECKING:  # what the segmenter provides
        working_width: int
        frame_flip: bool
        frame_scales: tuple[float, ...]
        frame_pooling: str
        labels: Any

        def _frame_pass(self, images: list[np.ndarray], stats: bool) -> tuple[np.ndarray, FrameTap | None]: ...

    def working_size(self, width: int, height: int) -> tuple[int, int]:
        """(width, height) of the working resolution for a frame of the given size."""
        return working_size(width, height, self.working_width)

    def predict_frame(self, rgb: np.ndarray, *, stats: bool = False) -> np.ndarray | FramePass:
        """Softmax of a frame at the working resolution.

        Parameters
        ----------
        rgb : ndarray of shape (H, W, 3), uint8
            The full-resolution frame.
        stats : bool
            Also return the statistics of the frame's first pass (first scale, not mirrored), for a frame gate.

        Returns
        -------
        ndarray of shape (8, h, w), float32, with ``(w, h) = working_size(W, H)``; with ``stats``, a
        :class:`~el.segmentation.frame_tap.FramePass` of it and the pass's ``FrameTap``.
        """
        check_frame_rgb(rgb, "frame")
        w, h = self.working_size(rgb.shape[1], rgb.shape[0])
        if (rgb.shape[1], rgb.shape[0]) != (w, h):
            rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
        check_frame_rgb(rgb, "frame at working resolution")
        total, tap = None, None
        for i, scale in enumerate(self.frame_scales):
            checkpoint("segmentation")  # the decision's deadline, between the network's passes
            probs, found = self._frame_at_scale(rgb, scale, stats and i == 0)
            if found is not None:
                tap = found
            total = probs if total is None else total + probs
        if len(self.frame_scales) > 1:
            total /= np.float32(len(self.frame_scales))
        return FramePass(total, tap) if stats else total

    def _frame_at_scale(self, rgb: np.ndarray, scale: float, stats: bool) -> tuple[np.ndarray, FrameTap | None]:
        """Softmax (8, h, w) of a working-resolution frame fed to the network resized by ``scale``, and with
        ``stats`` the statistics of that pass (the unmirrored image's)."""
        h, w = rgb.shape[:2]
        size = (max(MIN_SIZE, round(w * scale)), max(MIN_SIZE, round(h * scale)))
        view = rgb if size == (w, h) else cv2.resize(rgb, size, interpolation=cv2.INTER_LINEAR)
        if not self.frame_flip:
            batch, tap = self._frame_pass([view], stats)
            probs = batch[0]
        else:
            pair, tap = self._frame_pass([view, np.ascontiguousarray(view[:, ::-1])], stats)
            probs = 0.5 * (pair[0] + pair[1][:, :, ::-1])
        if size != (w, h):  # back to the working resolution, over each pixel's footprint
            probs = downsample_probs(probs, (w, h), self.frame_pooling, labels=self.labels)
        return np.ascontiguousarray(probs, dtype=np.float32), tap
