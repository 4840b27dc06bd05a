"""Several HD patches through a :class:`~el.segmentation.inference.Segmenter` at once, each with the scores it
gets alone (``predict_patch``): what a monitor judging every candidate of a frame calls (``predict_patches``).

Under ONNX Runtime the patches run side by side on single-threaded sessions, one per engine thread
(``el.segmentation.patch_pool``: a patch is too small to keep one session's threads busy). Otherwise patches of
one padded size share a batch (``el.segmentation.batching``: padded as the network pads them itself).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from el.base.deadline import checkpoint
from el.base.rgb import check_rgb
from el.segmentation.batching import group_by_padded_size, padded_batch, padding_multiple, unit_nchw
from el.segmentation.patch_pool import PatchPool

MIN_SIZE = 16  # as el.segmentation.inference.MIN_SIZE
MAX_WORKERS = 8  # sessions of the patch pool when the engine's thread count sets it
Then = Callable[[int, np.ndarray], Any]


def _softmax(k: int, probs: np.ndarray) -> np.ndarray:
    return probs


class PatchPasses:
    """The batched patch passes of a Segmenter (a mixin: it reads the segmenter's ``engine``, ``model``, ``labels``,
    ``_lock``, ``_to_tensor``, ``_probs`` and ``_engine_probs``: the softmax of ONNX Runtime's numpy logits). Under
    ONNX Runtime no torch is imported here (the torch-free ``el.segmentation.onnx_segmenter``)."""

    patch_workers: int | None = None  # ONNX Runtime sessions segmenting patches side by side (None: engine threads)
    if TYPE_CHECKING:  # what the segmenter provides
        engine: Any
        model: Any
        labels: Any
        _lock: Any

        def _to_tensor(self, images: list[np.ndarray]) -> Any: ...

        def _probs(self, logits: Any, shape: tuple[int, ...], what: str) -> np.ndarray: ...

        def _engine_probs(self, logits: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray: ...

    def predict_patches(self, patches: list[np.ndarray], *, then: Then | None = None) -> list[Any]:
        """Softmax of several patches, each as :meth:`predict_patch` gives it alone; the order is kept.

        Under ONNX Runtime with 2 or more :attr:`patch_workers`, each patch runs alone on one of the pool's
        single-threaded sessions, side by side (the same numbers as a lone pass). Otherwise patches of one padded
        size run as one batch: edge-padded to the network's stride before the pass, as the network pads them
        itself (``el.segmentation.batching``), then cropped back, so each keeps its own scores (a torch batch may
        differ from single passes in the last float bits).

        ``then(k, softmax)``: what to return for patch k instead of its softmax, run as soon as that is ready (on
        the worker that computed it: a monitor's features of patch k while the other patches segment).
        """
        then = then or _softmax
        for i, p in enumerate(patches):
            check_rgb(p, f"patch {i}", min_size=MIN_SIZE)
        pool = self._patch_pool() if len(patches) > 1 else None
        if pool is not None:  # ONNX Runtime: each patch alone, on single-threaded sessions side by side
            largest_first = sorted(range(len(patches)), key=lambda i: -patches[i].shape[0] * patches[i].shape[1])
            return pool.map([functools.partial(self._patch_then, p, k, then) for k, p in enumerate(patches)],
                            largest_first)
        out: list[Any] = [None] * len(patches)
        shapes = [p.shape[:2] for p in patches]
        for size, idx in group_by_padded_size(shapes, self._padding_multiple()).items():
            checkpoint("patch segmentation")
            probs = self._predict_cropped(padded_batch(patches, idx, size), [shapes[i] for i in idx])
            for i, p in zip(idx, probs, strict=True):
                out[i] = then(i, p)
        return out

    def _padding_multiple(self) -> int:
        """What the network edge-pads its input to (``el.segmentation.batching.padding_multiple``)."""
        return padding_multiple(self.model)

    def _patch_pool(self) -> PatchPool | None:
        """The sessions that segment patches side by side (``el.segmentation.patch_pool``), built at first use:
        :attr:`patch_workers` of them (None: one per thread of the engine, at most :data:`MAX_WORKERS`); None
        without ONNX Runtime or below 2."""
        engine = getattr(self, "engine", None)
        if engine is None:
            return None
        workers = self.patch_workers
        if workers is None:  # a frame has some 5 to 30 candidates: more sessions than MAX_WORKERS only cost memory
            workers = min(engine.threads or os.cpu_count() or 1, MAX_WORKERS)
        if workers < 2:
            return None
        with self._lock:
            pool = self.__dict__.get("_pool")
            if pool is None or len(pool.engines) != workers:
                pool = self._pool = PatchPool(lambda: engine.sibling(1), workers)
        return pool

    def _patch_then(self, rgb_patch: np.ndarray, k: int, then: Then, engine: Any) -> Any:
        """``then(k, softmax)`` of patch k, segmented on ``engine``: a pool worker's job."""
        return then(k, self._patch_on(rgb_patch, engine))

    def _patch_on(self, rgb_patch: np.ndarray, engine: Any) -> np.ndarray:
        """:meth:`predict_patch` of one patch on ``engine`` (one of the pool's sessions): the same computation."""
        checkpoint("patch segmentation")
        h, w = rgb_patch.shape[:2]
        logits = engine.logits(unit_nchw([rgb_patch]))
        return np.ascontiguousarray(self._engine_probs(logits, (1, self.labels.num_classes, h, w), "patch")[0])

    def _predict_cropped(self, images: list[np.ndarray], shapes: list[tuple[int, int]]) -> list[np.ndarray]:
        """Softmax of a batch of equal-size (padded) images, each cropped to its shape (h, w) before the softmax."""
        c = self.labels.num_classes
        if getattr(self, "engine", None) is not None:  # ONNX Runtime: numpy logits, no torch needed
            raw = self.engine.logits(unit_nchw(images))
            crops = [np.ascontiguousarray(raw[j:j + 1, :, :h, :w]) for j, (h, w) in enumerate(shapes)]  # a lone pass's
            return [np.ascontiguousarray(self._engine_probs(x, (1, c, h, w), "patch")[0])
                    for x, (h, w) in zip(crops, shapes, strict=True)]
        import torch  # a torch network's batch (the Segmenter of a torch module: torch is installed)

        with torch.inference_mode():
            logits = self.model(self._to_tensor(images))
            crops = [logits[j:j + 1, :, :h, :w] for j, (h, w) in enumerate(shapes)]  # as the network crops
            return [np.ascontiguousarray(self._probs(x, (1, c, h, w), "patch")[0])
                    for x, (h, w) in zip(crops, shapes, strict=True)]
