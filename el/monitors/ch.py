"""CH (classification hierarchy, on top of LHD): reject a disc holding an uncertain or unsafe pixel.

Each pixel is labelled with the closest common ancestor of its classes scoring above tau
(``hierarchy.yaml`` for UAVid; for another label set, the tree it declares or one derived from its
forbidden/safe split: ``el.monitors.hierarchy.default_hierarchy``); the disc is rejected if a pixel's
label has a forbidden class under it (``any``, ``unsafe`` or a forbidden class) or if LHD rejects it.
Score: the fraction of such pixels (``el.monitors.lhd.fraction_score``); threshold 0 is the paper's rule.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from el.classes.labels import LabelSet
from el.landing.forbidden import forbidden_pixels
from el.monitors.base import format_counts
from el.monitors.hierarchy import ClassHierarchy, default_hierarchy
from el.monitors.lhd import EMPTY_DISC, LHDMonitor, forbidden_counts, lhd_reason
from el.monitors.spec import MonitorSpec, validate_tau


def rejected_label_counts(pixel_scores: np.ndarray, tau: float, hierarchy: ClassHierarchy) -> dict[str, int]:
    """Count of pixels per rejected hierarchy label, for pixel scores (C, m) of the hierarchy's label set.

    Only inner nodes are counted (``any``, ``unsafe``): a pixel labelled with a forbidden class
    has that class as its only one above tau, hence as its top class, and LHD already counts it.
    """
    labels = hierarchy.label(pixel_scores, tau)
    bad = labels[hierarchy.rejected[labels] & (labels >= hierarchy.labels.num_classes)]
    if bad.size == 0:
        return {}
    ids, counts = np.unique(bad, return_counts=True)
    return {hierarchy.nodes[i]: int(c) for i, c in zip(ids, counts, strict=True)}


def ch_rule(pixel_scores: np.ndarray, tau: float, hierarchy: ClassHierarchy) -> tuple[bool, str]:
    """LHD + CH on the disc's pixel scores (C, m) of the hierarchy's label set: ``(accepted, reason)``."""
    m = pixel_scores.shape[1]
    if m == 0:
        return False, EMPTY_DISC
    parts = []
    forbidden = forbidden_counts(pixel_scores, hierarchy.labels)
    if forbidden:
        parts.append(lhd_reason(forbidden))
    uncertain = rejected_label_counts(pixel_scores, tau, hierarchy)
    if uncertain:
        parts.append(f"rejected hierarchy labels in disc (tau={tau!r}): {format_counts(uncertain)}")
    if parts:
        return False, "; ".join(parts)
    return True, f"no forbidden, unsafe or uncertain pixel in disc ({m} px)"


class CHMonitor(LHDMonitor):
    """LHD + CH with threshold ``tau`` (keyword-only), on the softmax of the HD patch.

    Parameters
    ----------
    tau : float in (0, 1)
        A class takes part in a pixel's label when its score is strictly above tau.
    hierarchy : ClassHierarchy, optional
        Defaults to the label set's (``default_hierarchy(labels)``: the shipped ``hierarchy.yaml`` for UAVid);
        one given must be over ``labels``.
    labels : LabelSet
        The label set of the segmenter's scores (any number of classes).
    margin, max_side, clock
        See ``Monitor``.
    """

    def __init__(self, *, tau: float, labels: LabelSet, hierarchy: ClassHierarchy | None = None,
                 **kwargs: Any) -> None:
        super().__init__(labels=labels, **kwargs)
        self.tau = validate_tau(tau)
        self.hierarchy = hierarchy if hierarchy is not None else default_hierarchy(labels)
        if self.hierarchy.labels != labels:
            raise ValueError(f"the CH hierarchy is over the label set {self.hierarchy.labels.name!r}, "
                             f"the monitor's is {labels.name!r}")

    @property
    def spec(self) -> MonitorSpec:
        return MonitorSpec(tau=self.tau, threshold=self.threshold)

    def rule(self, pixel_scores: np.ndarray) -> tuple[bool, str]:
        return ch_rule(pixel_scores, self.tau, self.hierarchy)

    def rejected_pixels(self, pixel_scores: np.ndarray) -> np.ndarray:
        """(m,) bool: forbidden by argmax, or labelled with a hierarchy node that has a forbidden class under it."""
        labels = self.hierarchy.label(pixel_scores, self.tau)
        return forbidden_pixels(pixel_scores, self.labels) | self.hierarchy.rejected[labels]

