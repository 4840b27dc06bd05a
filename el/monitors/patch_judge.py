"""The score walk's judge over one batched judgement of the frame: what the flight loop plugs into ``el.monitors.walk``.

A score walk (``learned:walk=score``; the deployed ``verifier:fuse=learned,walk=score``) judges every candidate
of the frame before it picks one, so nothing is lost by judging them together: :func:`batch_judge` returns a
judge that, at its first call, asks ``monitor.check_many`` for every candidate (a patch monitor then segments
their HD patches in few batched passes, ``el.monitors.patch_batch``) and afterwards serves each candidate's
verdict from that batch. The
verdicts live in the judge's closure, built for one frame: nothing outlives the decision, so no verdict can be
served for another frame. A hazard walk stops at the first accepted candidate and keeps the per-candidate judge.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from el.base.decision import Candidate, MonitorVerdict
from el.monitors.base import CandidateContext, Monitor

Judge = Callable[[int], MonitorVerdict]


def frame_contexts(candidates: Sequence[Candidate], probs: np.ndarray | None, rgb: np.ndarray
                   ) -> list[CandidateContext | None]:
    """Each candidate's context on the frame (None for every candidate when there is no frame softmax)."""
    size = (rgb.shape[1], rgb.shape[0])
    return [None if probs is None else CandidateContext(c, probs, size) for c in candidates]


def batch_judge(monitor: Monitor, rgb: np.ndarray, candidates: Sequence[Candidate], segmenter: Any, *,
                probs: np.ndarray | None, seed: int) -> Judge:
    """A judge of candidate ``k`` (hazard rank order) that judges all ``candidates`` of the frame at its first call
    (``monitor.check_many``, candidate k with seed ``seed + k`` and its context on ``probs``), the verdicts each
    ``monitor.check`` would give; raises what ``check_many`` raises, at that first call."""
    candidates = list(candidates)
    seeds = [seed + k for k in range(len(candidates))]
    verdicts: list[MonitorVerdict] = []

    def judge(k: int) -> MonitorVerdict:
        if not verdicts:
            verdicts.extend(monitor.check_many(rgb, candidates, segmenter, seeds=seeds,
                                               contexts=frame_contexts(candidates, probs, rgb)))
            if len(verdicts) != len(candidates):
                raise ValueError(f"{monitor.name}: {len(verdicts)} verdicts for {len(candidates)} candidates")
        return verdicts[k]

    return judge
