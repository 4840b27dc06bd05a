"""Bringing a softmax map down to a coarser grid without losing a forbidden class.

When the network sees the working frame enlarged (``frame_scales`` > 1), its softmax must come back
to the working resolution. Averaging over each working pixel's footprint (``area``) can dilute a thin
hazard (a narrow road, one car) that only some of the source pixels show, freeing a landing disc
beside it. ``conservative`` pooling keeps the forbidden classes' evidence instead: over each working
pixel's footprint, the **maximum** probability of each forbidden class and the **minimum** of each safe
class, renormalised to sum to 1. Then, if any source pixel's top class is forbidden (ties forbidden,
as :func:`el.monitors.lhd.forbidden_pixels` reads them), the working pixel's top class is forbidden
too: max over forbidden >= that pixel's forbidden >= its safe >= min over safe. This mirrors the
conservative downsampling of label maps in the core model.
"""

from __future__ import annotations

import numpy as np

from el.base.torch_extra import require_torch
from el.classes.labels import LabelSet

POOLINGS = ("area", "conservative")


def check_pooling(name: object) -> str:
    if name not in POOLINGS:
        raise ValueError(f"frame_pooling must be one of {', '.join(POOLINGS)}, got {name!r}")
    return str(name)


def downsample_probs(probs: np.ndarray, size: tuple[int, int], pooling: str = "area", *,
                     labels: LabelSet | None = None) -> np.ndarray:
    """Softmax (C, H, W) -> (C, h, w) for ``size = (w, h)`` no larger than the input, by ``pooling``.

    ``area``: mean over each output pixel's footprint (OpenCV ``INTER_AREA``). ``conservative``: see
    the module docstring; footprints are the source rows ``floor(i H / h) .. ceil((i + 1) H / h) - 1``
    (and likewise columns), every source pixel that overlaps the output pixel. ``labels``: which
    classes are forbidden, needed by ``conservative`` (C must be its class count); ``area`` reads no class.
    """
    check_pooling(pooling)
    c, h_in, w_in = probs.shape
    w, h = size
    if w > w_in or h > h_in:
        raise ValueError(f"cannot pool {w_in}x{h_in} up to {w}x{h}")
    if pooling == "area":
        import cv2

        return np.stack([cv2.resize(ch, (w, h), interpolation=cv2.INTER_AREA) for ch in probs])
    if labels is None:
        raise ValueError("conservative pooling needs the label set (which classes are forbidden)")
    if c != labels.num_classes:
        raise ValueError(f"conservative pooling needs the {labels.num_classes} classes, got {c}")
    # torch: the optional heavy dependency (the train extra), imported only for conservative pooling
    torch = require_torch("conservative frame pooling")
    F = torch.nn.functional
    forbidden, safe = list(labels.forbidden_ids), list(labels.safe_ids)
    t = torch.from_numpy(np.ascontiguousarray(probs, dtype=np.float32))[None]
    out = torch.empty((1, c, h, w), dtype=torch.float32)
    out[:, forbidden] = F.adaptive_max_pool2d(t[:, forbidden], (h, w))
    out[:, safe] = -F.adaptive_max_pool2d(-t[:, safe], (h, w))
    out /= out.sum(dim=1, keepdim=True).clamp_min(1e-12)
    return out[0].numpy()
