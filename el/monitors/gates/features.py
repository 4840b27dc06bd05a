"""The features a frame gate reads from a frame's tap (``el.segmentation.frame_tap.FrameTap``)."""

from __future__ import annotations

from typing import Any

import numpy as np

WHAT = {"pooled": "per-channel mean and standard deviation over space of every trunk level of the frame pass "
                  "(el.segmentation.frame_tap)",
        "output": "per-class mean and standard deviation over space of the frame pass's logits "
                  "(el.segmentation.frame_tap)",
        "energy": "mean over pixels of -logsumexp of the frame logits"}
"""What each tap feature is (recorded in a fitted gate's file)."""


def tap_vector(tap: Any, features: str) -> np.ndarray:
    """The feature vector ``features`` (``pooled``, ``output`` or ``energy``) of a frame's tap; ValueError naming
    what the network's pass did not keep."""
    if features == "energy":
        return np.array([tap.energy], np.float64)
    if features not in ("pooled", "output"):
        raise ValueError(f"unknown frame-gate features {features!r}; known: {', '.join(WHAT)}")
    value = getattr(tap, features, None)
    if value is None:
        if features == "pooled":
            raise ValueError("this gate reads the trunk's features; the network's frame pass gives the logits only "
                             "(no trunk outputs): fit the gate on its output (uav-el fit-gate --features output)")
        raise ValueError("this gate reads the output's statistics, which the network's frame pass did not keep")
    return np.asarray(value, np.float64)
