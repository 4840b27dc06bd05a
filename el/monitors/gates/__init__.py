"""Frame gates: candidates for the out-of-domain frame gate, each one file behind one interface.

A gate reads the frame's :class:`el.segmentation.frame_tap.FrameTap` (what the segmentation pass already
computed: no second pass) and returns a score, higher = further from the training frames. Each module defines
``NAME``, ``FEATURES`` (the tap's features it can read, the first its default: ``energy``, or ``pooled``, the
trunk's statistics, and ``output``, the logits' statistics, which every network has), ``embed(tap, features)
-> (d,)``, ``fit(train (n, d)) -> params`` (plain JSON data) and ``score(params, x (n, d)) -> (n,)``. The threshold
is set outside (a quantile of validation frames).
"""

from __future__ import annotations

from types import ModuleType

from el.monitors.gates import energy, knn, mahalanobis
from el.monitors.gates.features import WHAT, tap_vector

GATES: dict[str, ModuleType] = {m.NAME: m for m in (energy, mahalanobis, knn)}

__all__ = ["GATES", "WHAT", "tap_vector"]
