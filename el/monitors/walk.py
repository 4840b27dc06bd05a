"""The order in which the decision loop examines candidates (docs/architecture.md section 3.7).

``hazard`` (the paper's): best hazard rank first; the drone lands on the first candidate the monitor
accepts, and candidates after it are never judged. ``score``: every candidate is judged first, then
they are walked by ascending monitor score (ties by hazard rank), so the drone lands on the accepted
candidate its monitor finds least likely unsafe. A registered monitor takes it as ``walk=score``
(``learned:walk=score``); the paper's monitors walk by hazard.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

HAZARD, SCORE = "hazard", "score"
WALKS = (HAZARD, SCORE)


def check_walk(value: str) -> str:
    """A valid walk name (``hazard`` or ``score``)."""
    v = str(value).lower()
    if v not in WALKS:
        raise ValueError(f"walk must be one of {', '.join(WALKS)}, got {value!r}")
    return v


def walk_order(scores: Sequence[float], walk: str) -> list[int]:
    """Candidate indices (hazard rank order) in the order the walk examines them."""
    idx = list(range(len(scores)))
    if check_walk(walk) == HAZARD:
        return idx
    if not all(math.isfinite(float(s)) for s in scores):
        raise ValueError("a score walk needs finite monitor scores")
    return sorted(idx, key=lambda k: (float(scores[k]), k))


def select(accepted: Sequence[bool], scores: Sequence[float], walk: str) -> int | None:
    """The candidate the walk lands on: the first accepted in walk order, or None (default action)."""
    for k in walk_order(scores, walk):
        if accepted[k]:
            return k
    return None
