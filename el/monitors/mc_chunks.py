"""MC dropout in chunks, so a time budget binds inside the monitor and memory stays bounded.

``Segmenter.mc_dropout`` runs all ``n`` samples as one batch: with ``n = 1000`` that is tens of
seconds and gigabytes before the decision loop can look at its clock. ``mc_samples`` draws the same
dropout masks (one draw of ``n``, sample by sample from the seeded generator, so any chunk of it is
the matching slice of the whole: the masks are prefix-consistent) and runs the network's
stochastic head ``chunk`` samples at a time, calling ``between(seconds_of_last_chunk)`` between
chunks: the caller's budget check, which raises to stop. At most ``chunk`` samples of activations
are alive at once.

A draw of at most ``chunk`` samples, or a segmenter without the trunk/head split, is one call of
``mc_dropout`` exactly as before (the same bytes); larger draws give the one-batch samples up to the
float rounding of batched convolutions (~1e-7).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from el.base.deadline import checkpoint

MC_CHUNK = 32
"""Samples per batch: above the shipped configurations' n (10, 30), so their samples are unchanged."""

Between = Callable[[float], None]


def can_chunk(segmenter: Any) -> bool:
    """Whether the segmenter exposes what chunking needs (the shipped ``Segmenter`` does)."""
    model = getattr(segmenter, "model", None)
    return bool(getattr(segmenter, "fast_mc", False) and model is not None
                and all(callable(getattr(model, a, None)) for a in ("trunk", "head_logits", "mc_spec"))
                and hasattr(model, "logit_stride"))


@dataclass(frozen=True, kw_only=True)
class Chunking:
    """How a draw is cut: ``chunk`` samples at a time, ``between(seconds)`` called after each chunk but the last with
    the time that chunk took on ``clock`` (it raises to abandon the draw: a budget about to run out; None: no call).
    ``chunk`` is checked when a draw is cut (ValueError below 1)."""

    chunk: int = MC_CHUNK
    between: Between | None = None
    clock: Callable[[], float] = time.perf_counter


def mc_samples(segmenter: Any, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int, *,
               window: tuple[int, int, int, int] | None = None, chunking: Chunking | None = None) -> np.ndarray:
    """``n`` MC-dropout softmax samples (n, 8, h, w) of a patch (h, w: the window's, when given), drawn in chunks as
    ``chunking`` says (:class:`Chunking`; None: its defaults)."""
    chunking = chunking or Chunking()
    chunk, between, clock = chunking.chunk, chunking.between, chunking.clock
    kw: dict[str, Any] = {} if window is None else {"window": window}
    if n <= chunk or float(keep_prob) == 1.0 or not can_chunk(segmenter):
        return segmenter.mc_dropout(rgb_patch, n, keep_prob, seed, **kw)
    import torch

    from el.segmentation.inference import softmax_classes  # deferred: imports torch (the train extra)
    from el.segmentation.model import MCSpec, upsample_logits  # deferred: imports torch, as above

    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk!r}")
    if not (isinstance(rgb_patch, np.ndarray) and rgb_patch.ndim == 3 and rgb_patch.shape[2] == 3
            and rgb_patch.dtype == np.uint8):
        raise ValueError("patch must be a uint8 (h, w, 3) array")
    h, w = rgb_patch.shape[:2]
    y0, y1, x0, x1 = window if window is not None else (0, h, 0, w)
    if not (0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w):
        raise ValueError(f"window {window!r} is not a non-empty box inside the {h}x{w} patch")
    model = segmenter.model
    spec = model.mc_spec(int(n), float(keep_prob), int(seed))  # the whole draw: masks are cheap
    x = torch.from_numpy(rgb_patch[None].astype(np.float32) / np.float32(255.0)).permute(0, 3, 1, 2)
    x = x.contiguous().to(getattr(segmenter, "device", "cpu"))
    parts: list[np.ndarray] = []
    with torch.inference_mode():
        features = model.trunk(x)
        for a in range(0, n, chunk):
            checkpoint("MC dropout")
            t = clock()
            b = min(n, a + chunk)
            sub = MCSpec([m[a:b] for m in spec.masks])
            low = model.head_logits(features.repeat(b - a), sub)
            probs = upsample_logits(low.float(), model.logit_stride, (y0, y1, x0, x1), then=softmax_classes)
            part = np.ascontiguousarray(probs.cpu().numpy(), dtype=np.float32)
            if part.shape != (b - a, 8, y1 - y0, x1 - x0) or not np.isfinite(part).all():
                raise ValueError(f"MC dropout: model returned {part.shape} or non-finite scores")
            parts.append(part)
            if b < n and between is not None:
                between(clock() - t)
    return np.concatenate(parts, axis=0)
