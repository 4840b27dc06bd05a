"""Every monitor's verdict on every candidate of one frame, sharing work: the campaign's side of the monitors.

The flight interface (``el.monitors.Monitor``) judges one candidate at a time. A campaign judges every
candidate with many configurations, so for the monitors written as ``PatchMonitor`` steps it crops
each patch once, runs the segmenter's trunk once, computes each kind of features once (drawn by the
monitor that needs the most samples) and each reduction once, and charges every configuration what it
would have spent alone. Any other monitor is judged on its own through ``check``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import numpy as np

from el.decision import Candidate, MonitorVerdict
from el.monitors import CandidateContext, Monitor, PatchMonitor
from el.segmentation.contract import PATCH_TRUNK, has_capability
from el.walk import check_verdict


def _timed(clock: Callable[[], float], fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float]:
    t = clock()
    out = fn(*args, **kwargs)
    return out, clock() - t


def share_seconds(seconds: float, needed: int, drawn: int) -> float:
    """What features of ``needed`` samples cost alone, from ``seconds`` for ``drawn`` shared samples
    (MC dropout runs the head once per sample: a monitor pays its share of the batch)."""
    return seconds if drawn <= needed else seconds * needed / drawn


def feature_owners(monitors: Sequence[PatchMonitor]) -> dict[Hashable, PatchMonitor]:
    """Feature key -> the monitor that draws the most samples of it (the others take a prefix)."""
    owners: dict[Hashable, PatchMonitor] = {}
    for m in monitors:
        held = owners.get(m.feature_key)
        if held is None or m.feature_size > held.feature_size:
            owners[m.feature_key] = m
    return owners


def judge_candidates(
    hd: np.ndarray,
    candidates: Sequence[Candidate],
    monitors: Sequence[Monitor],
    segmenter: Any,
    *,
    seed: int,
    clock: Callable[[], float] = time.perf_counter,
    frame_probs: np.ndarray | None = None,
) -> list[list[MonitorVerdict]]:
    """Every monitor's verdict on every candidate; ``[candidate][monitor]`` (in the order given).

    ``frame_probs`` (the frame's softmax) reaches monitors that read it (``CandidateContext``).
    """
    shared = [m for m in monitors if isinstance(m, PatchMonitor)]
    if len({(m.margin, m.max_side) for m in shared}) > 1:
        raise ValueError("monitors of one campaign must share the patch margin and max_side")
    owners = feature_owners(shared)
    has_trunk = has_capability(segmenter, PATCH_TRUNK)
    size = (hd.shape[1], hd.shape[0])
    out: list[list[MonitorVerdict]] = []
    for k, cand in enumerate(candidates):
        context = None if frame_probs is None else CandidateContext(cand, frame_probs, size)
        row: dict[int, MonitorVerdict] = {}
        if shared:
            row.update(_judge_shared(hd, cand, shared, owners, segmenter, seed=seed + k, clock=clock,
                                     context=context, has_trunk=has_trunk))
        for m in monitors:
            if not isinstance(m, PatchMonitor):
                row[id(m)] = m.check(hd, cand, segmenter, seed=seed + k, context=context)
        out.append([check_verdict(row[id(m)]) for m in monitors])  # the walk's own check, inside the task
    return out


def _judge_shared(hd: np.ndarray, cand: Candidate, monitors: Sequence[PatchMonitor],
                  owners: dict[Hashable, PatchMonitor], segmenter: Any, *, seed: int, clock: Callable[[], float],
                  context: CandidateContext | None, has_trunk: bool) -> dict[int, MonitorVerdict]:
    """The patch monitors' verdicts on one candidate, each step computed once for all of them."""
    patch, t_patch = _timed(clock, monitors[0].patch, hd, cand)
    trunk, t_trunk = _timed(clock, segmenter.patch_trunk, patch.rgb) if has_trunk else (None, 0.0)
    features = {}
    for key, owner in owners.items():
        (feats, mask), t_feat = _timed(clock, owner.patch_features, patch, segmenter, seed=seed,
                                       size=owner.feature_size, trunk=trunk, context=context)
        features[key] = (feats, mask, t_feat, owner.feature_size)
    reduced: dict[Any, tuple[Any, float]] = {}
    verdicts = {}
    for m in monitors:
        feats, mask, t_feat, drawn = features[m.feature_key]
        rkey = (m.feature_key, m.reduce_key)
        if rkey not in reduced:  # e.g. LHD and the CH taus read the same disc pixels: take them once
            reduced[rkey] = _timed(clock, m.reduce, feats, mask)
        red, t_red = reduced[rkey]
        judgement, t_judge = _timed(clock, m.judge, red)
        seconds = t_patch + t_trunk + share_seconds(t_feat, m.feature_size, drawn) + t_red + t_judge
        verdicts[id(m)] = MonitorVerdict(m.name, bool(judgement.accepted), judgement.reason, seconds,
                                         float(judgement.score), m.threshold)
    return verdicts

