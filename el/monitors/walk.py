"""The decision walk (docs/architecture.md section 3.7): which candidate the drone lands on, and why.

One function, :func:`walk_candidates`, that the decision loop (``el.flight.pipeline``), the ground-truth
pipeline and a campaign's judging all call, so the three cannot disagree on a decision:

- ``hazard`` (the paper's walk): best hazard rank first; the drone lands on the first candidate the
  monitor accepts, and candidates after it are never judged (unless ``evaluate_all``, for readouts);
- ``score``: every candidate is judged first, then they are walked by ascending monitor score (ties
  by hazard rank), so the drone lands on the accepted candidate its monitor finds least likely
  unsafe. A registered monitor takes it as ``walk=score`` (``learned:walk=score``).

Without a monitor the drone lands on the CM's top candidate. The outcome's reason is one of
:data:`ACCEPTED`, :data:`NO_CANDIDATE` and :data:`ALL_REJECTED`, written here only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from el.base.decision import MonitorVerdict

HAZARD, SCORE = "hazard", "score"
WALKS = (HAZARD, SCORE)
ACCEPTED, NO_CANDIDATE, ALL_REJECTED = "accepted", "no_candidate", "all_rejected"

Judge = Callable[[int], MonitorVerdict]
"""The monitor's verdict on candidate ``k`` (hazard rank order)."""
Step = Callable[[int, bool], None]
"""Called with ``(k, real)`` around each judgement; ``real``: the judgement is part of the walk that decides
(False for the evaluation-only judgements past the decision). The decision loop checks its budget here."""


@dataclass(frozen=True)
class WalkOutcome:
    """Where the walk ended: the selected candidate (None: the default action) and why.

    ``verdicts[k]``: the verdict on candidate k, None where it was not judged; ``examined``: how many
    candidates the deciding walk judged; ``overhead_s``: the monitoring seconds of those judgements.
    """

    selected: int | None
    reason: str
    verdicts: tuple[MonitorVerdict | None, ...]
    examined: int
    overhead_s: float

    @property
    def action(self) -> str:
        return "default" if self.selected is None else "land"


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


def outcome_reason(candidates: int, selected: int | None) -> str:
    """The reason of a walk's outcome: accepted, no_candidate or all_rejected."""
    if selected is not None:
        return ACCEPTED
    return NO_CANDIDATE if candidates == 0 else ALL_REJECTED


def walk_candidates(n: int, judge: Judge | None, walk: str = HAZARD, *, evaluate_all: bool = False,
                    before: Step | None = None, after: Step | None = None) -> WalkOutcome:
    """Walk ``n`` ranked candidates with a monitor's ``judge`` (None: no monitor, the top candidate).

    ``evaluate_all`` judges the candidates a hazard walk would leave after its decision too (their
    verdicts do not change it). ``before``/``after`` are called around each judgement (see :data:`Step`).
    """
    if judge is None:
        selected = 0 if n else None
        return WalkOutcome(selected, outcome_reason(n, selected), (None,) * n, 0, 0.0)
    verdicts: list[MonitorVerdict | None] = [None] * n
    if check_walk(walk) == SCORE:
        for k in range(n):
            _call(before, k, True)
            verdicts[k] = check_verdict(judge(k))
            _call(after, k, True)
        judged = [v for v in verdicts if v is not None]
        selected = select([v.accepted for v in judged], [v.score for v in judged], SCORE)
        overhead = 0.0
        for v in judged:
            overhead += v.seconds
        return WalkOutcome(selected, outcome_reason(n, selected), tuple(verdicts), n, overhead)
    selected, examined, overhead = None, 0, 0.0
    for k in range(n):
        real = selected is None
        if not real and not evaluate_all:
            break
        _call(before, k, real)
        verdict = verdicts[k] = check_verdict(judge(k))
        if real:
            examined, overhead = k + 1, overhead + verdict.seconds
            if verdict.accepted:
                selected = k
        _call(after, k, real)
    return WalkOutcome(selected, outcome_reason(n, selected), tuple(verdicts), examined, overhead)


def _call(step: Step | None, k: int, real: bool) -> None:
    if step is not None:
        step(k, real)


def check_verdict(verdict: object) -> MonitorVerdict:
    """A verdict the walk may act on: a MonitorVerdict whose boolean verdict is its score at its threshold."""
    if not isinstance(verdict, MonitorVerdict):
        raise ValueError(f"monitor returned {type(verdict).__name__}, not a MonitorVerdict")
    if not isinstance(verdict.accepted, bool | np.bool_):
        raise ValueError(f"{verdict.name}: verdict must be true or false, got {verdict.accepted!r}")
    score, threshold = float(verdict.score), float(verdict.threshold)
    if math.isnan(score):
        raise ValueError(f"{verdict.name}: non-finite score (NaN)")
    if not math.isnan(threshold) and bool(verdict.accepted) != (not score > threshold):
        raise ValueError(f"{verdict.name}: verdict {'accepted' if verdict.accepted else 'rejected'} contradicts "
                         f"score {score:.6g} at threshold {threshold:.6g}")
    return verdict
