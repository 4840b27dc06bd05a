"""Every monitor's verdict on every candidate of one frame, sharing work, and the walk that decides."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from el.decision import Candidate
from el.monitors import CandidateContext, Monitor
from el.monitors.walk import HAZARD, select


def _timed(clock: Callable[[], float], fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float]:
    t = clock()
    out = fn(*args, **kwargs)
    return out, clock() - t


def judge_candidates(
    hd: np.ndarray,
    candidates: Sequence[Candidate],
    monitors: Sequence[Monitor],
    segmenter: Any,
    *,
    seed: int,
    clock: Callable[[], float] = time.perf_counter,
    frame_probs: np.ndarray | None = None,
) -> list[list[tuple[bool, str, float, float]]]:
    """Every monitor's verdict on every candidate, sharing work; [candidate][monitor] ->
    (accepted, reason, attributed seconds, score).

    Only the monitor interface is used: per candidate, the HD patch and the segmenter's trunk once
    (when it has ``patch_trunk``), then the features once per ``feature_key`` (drawn by the monitor
    that needs the most samples), the ``reduce`` step once per ``reduce_key``, and each monitor's
    ``judge``. Each configuration is charged what it would have spent alone: the patch, the trunk,
    its share of its features (``feature_seconds``), the reduction and its judgement.
    ``frame_probs`` (the frame's softmax) reaches monitors that read it (``CandidateContext``).
    """
    margins = {(m.margin, m.max_side) for m in monitors}
    if len(margins) != 1:
        raise ValueError("monitors of one campaign must share the patch margin and max_side")
    owners: dict[Any, Monitor] = {}  # feature key -> the monitor that draws the most samples of it
    for m in monitors:
        held = owners.get(m.feature_key)
        if held is None or m.feature_size > held.feature_size:
            owners[m.feature_key] = m
    # Optional Segmenter speed-up; any object with the PatchSegmenter methods still works.
    has_trunk = callable(getattr(segmenter, "patch_trunk", None))
    size = (hd.shape[1], hd.shape[0])
    out: list[list[tuple[bool, str, float, float]]] = []
    for k, cand in enumerate(candidates):
        patch, t_patch = _timed(clock, monitors[0].patch, hd, cand)
        trunk, t_trunk = _timed(clock, segmenter.patch_trunk, patch.rgb) if has_trunk else (None, 0.0)
        context = None if frame_probs is None else CandidateContext(cand, frame_probs, size)
        features = {}
        for key, owner in owners.items():
            (feats, mask), t_feat = _timed(clock, owner.patch_features, patch, segmenter, seed=seed + k,
                                           size=owner.feature_size, trunk=trunk, context=context)
            features[key] = (feats, mask, t_feat, owner.feature_size)
        reduced: dict[Any, tuple[Any, float]] = {}
        row = []
        for m in monitors:
            feats, mask, t_feat, drawn = features[m.feature_key]
            rkey = (m.feature_key, m.reduce_key)
            if rkey not in reduced:  # e.g. LHD and the CH taus read the same disc pixels: take them once
                reduced[rkey] = _timed(clock, m.reduce, feats, mask)
            red, t_red = reduced[rkey]
            judgement, t_judge = _timed(clock, m.judge, red)
            if math.isnan(judgement.score):
                raise ValueError(f"{m.name}: non-finite score (NaN)")
            seconds = t_patch + t_trunk + m.feature_seconds(t_feat, drawn) + t_red + t_judge
            row.append((bool(judgement.accepted), judgement.reason, seconds, float(judgement.score)))
        out.append(row)
    return out


def walk(verdicts: Sequence[bool], scores: Sequence[float] | None = None, order: str = HAZARD) -> int | None:
    """The decision loop's walk (``el.monitors.walk``): the candidate it lands on, or None (default)."""
    return select(verdicts, scores if scores is not None else [0.0] * len(verdicts), order)
