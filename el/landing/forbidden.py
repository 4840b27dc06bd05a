"""The one forbidden-pixel rule: a forbidden class wins the argmax, and a tie counts as forbidden.

The core model reads the working-resolution softmax by it (``el.landing.candidates.forbidden_from_probs``),
the monitors read their HD patch scores by it (``el.monitors.lhd``) and the harness's evidence scores
use it too (``assurance.fitting.separation``): one definition, so that "forbidden" means the same pixels
everywhere (docs/architecture.md sections 3.3 and 3.6). Which classes are forbidden is the label set's
word (``labels``, default :data:`el.classes.labels.UAVID`).
"""

from __future__ import annotations

import numpy as np

from el.classes.labels import LabelSet


def top_scores(scores: np.ndarray, labels: LabelSet) -> tuple[np.ndarray, np.ndarray]:
    """(top forbidden score, top safe score) per pixel of ``scores`` of shape (C, ...), C = ``labels.num_classes``.

    Element-wise maxima without copying the class planes (a frame's softmax is large); the values
    are exactly ``scores[ids].max(axis=0)``.
    """
    forbidden_ids, safe_ids = labels.forbidden_ids, labels.safe_ids
    top_forbidden = scores[forbidden_ids[0]]
    for c in forbidden_ids[1:]:
        top_forbidden = np.maximum(top_forbidden, scores[c])
    top_safe = scores[safe_ids[0]]
    for c in safe_ids[1:]:
        top_safe = np.maximum(top_safe, scores[c])
    return top_forbidden, top_safe


def forbidden_pixels(scores: np.ndarray, labels: LabelSet) -> np.ndarray:
    """Bool of shape (...): True where the top-scoring class of ``scores`` (C, ...) is forbidden, ties included."""
    top_forbidden, top_safe = top_scores(scores, labels)
    return top_forbidden >= top_safe


def argmax_slack(scores: np.ndarray, labels: LabelSet) -> np.ndarray:
    """Top forbidden score minus top safe score per pixel (>= 0 exactly where :func:`forbidden_pixels`)."""
    top_forbidden, top_safe = top_scores(scores, labels)
    return top_forbidden - top_safe
