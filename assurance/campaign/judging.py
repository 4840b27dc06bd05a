"""Every monitor's verdict on every candidate of one frame, sharing work: the campaign's side of the monitors.

The flight interface (``el.monitors.Monitor``) judges one candidate at a time. A campaign judges every
candidate with many configurations, so for the monitors written as ``PatchMonitor`` steps it crops
each patch once, runs the segmenter's trunk once, computes each kind of features once (drawn by the
monitor that needs the most samples) and each reduction once, and charges every configuration what it
would have spent alone. Any other monitor is judged on its own through ``check``.

A configuration that fails (its features, its reduction, its judgement, a verdict the walk refuses) fails alone
when the caller collects ``faults``: it is recorded there and left out of the rest of the frame, and every other
configuration is judged as if it were not there (a step shared by several fails them all).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from el.base.decision import Candidate, MonitorVerdict
from el.monitors import CandidateContext, Monitor, PatchMonitor
from el.monitors.walk import check_verdict
from el.segmentation.contract import PATCH_TRUNK, has_capability


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
    faults: dict[int, str] | None = None,
) -> list[list[MonitorVerdict | None]]:
    """Every monitor's verdict on every candidate; ``[candidate][monitor]`` (in the order given).

    ``frame_probs`` (the frame's softmax) reaches monitors that read it (``CandidateContext``). ``faults``: None, a
    monitor's failure is raised; a dict, it is recorded there (monitor index -> ``"Error: message"``, as a task's
    fault) and that monitor's verdicts are None from then on, the others' unchanged. Monitors already in ``faults``
    are not judged.
    """
    isolate = faults is not None
    faults = {} if faults is None else faults
    shared = [m for m in monitors if isinstance(m, PatchMonitor)]
    if len({(m.margin, m.max_side) for m in shared}) > 1:
        raise ValueError("monitors of one campaign must share the patch margin and max_side")
    index = {id(m): i for i, m in enumerate(monitors) if m is not None}  # None: a configuration already faulted
    owners = feature_owners(shared)  # of every configuration: one that faulted changes no other's draw
    frame_pass = _FramePass(segmenter, has_capability(segmenter, PATCH_TRUNK), clock)
    size = (hd.shape[1], hd.shape[0])
    out: list[list[MonitorVerdict | None]] = []
    for k, cand in enumerate(candidates):
        context = None if frame_probs is None else CandidateContext(cand, frame_probs, size)
        row: dict[int, MonitorVerdict] = {}
        failed: dict[int, str] = {}
        live = [m for m in shared if index[id(m)] not in faults]
        if live:
            needed = {key: owners[key] for key in dict.fromkeys(m.feature_key for m in live)}
            row.update(_judge_shared(hd, cand, live, needed, frame_pass, seed=seed + k, context=context,
                                     failed=failed if isolate else None))
        for i, m in enumerate(monitors):
            if not isinstance(m, PatchMonitor) and i not in faults:
                with _isolated(failed if isolate else None, id(m)):
                    row[id(m)] = m.check(hd, cand, segmenter, seed=seed + k, context=context)
        for i, m in enumerate(monitors):
            if i not in faults and id(m) not in failed:
                with _isolated(failed if isolate else None, id(m)):
                    check_verdict(row[id(m)])  # the walk's own check, inside the task
            if i not in faults and id(m) in failed:
                faults[i] = failed[id(m)]
        out.append([None if i in faults else row[id(m)] for i, m in enumerate(monitors)])
    return out


@contextmanager
def _isolated(failed: dict[int, str] | None, key: int) -> Iterator[None]:
    """The block's exception, with ``failed`` (isolation on), recorded there under ``key`` instead of raised."""
    if failed is None:
        yield
        return
    try:
        yield
    except Exception as exc:  # one configuration's fault: recorded, the others go on
        failed.setdefault(key, f"{type(exc).__name__}: {exc}")


@dataclass(frozen=True)
class _FramePass:
    """What every candidate of a frame is judged with: the segmenter, whether it shares a patch's trunk
    (``PATCH_TRUNK``), and the clock that times each step."""

    segmenter: Any
    has_trunk: bool
    clock: Callable[[], float]


def _judge_shared(hd: np.ndarray, cand: Candidate, monitors: Sequence[PatchMonitor],
                  owners: dict[Hashable, PatchMonitor], frame_pass: _FramePass, *, seed: int,
                  context: CandidateContext | None, failed: dict[int, str] | None = None) -> dict[int, MonitorVerdict]:
    """The patch monitors' verdicts on one candidate, each step computed once for all of them; with ``failed``, a
    step's failure is recorded for every monitor that needs it (by ``id``) instead of raised."""
    segmenter, has_trunk, clock = frame_pass.segmenter, frame_pass.has_trunk, frame_pass.clock
    try:
        patch, t_patch = _timed(clock, monitors[0].patch, hd, cand)
        trunk, t_trunk = _timed(clock, segmenter.patch_trunk, patch.rgb) if has_trunk else (None, 0.0)
    except Exception as exc:  # every patch monitor needs the patch and the trunk
        if failed is None:
            raise
        failed.update({id(m): f"{type(exc).__name__}: {exc}" for m in monitors})
        return {}
    features, broken = {}, {}
    for key, owner in owners.items():
        try:
            (feats, mask), t_feat = _timed(clock, owner.patch_features, patch, segmenter, seed=seed,
                                           size=owner.feature_size, trunk=trunk, context=context)
            features[key] = (feats, mask, t_feat, owner.feature_size)
        except Exception as exc:  # every monitor reading these features
            if failed is None:
                raise
            broken[key] = f"{type(exc).__name__}: {exc}"
    reduced: dict[Any, tuple[Any, float]] = {}
    verdicts = {}
    for m in monitors:
        if failed is not None and m.feature_key in broken:
            failed[id(m)] = broken[m.feature_key]
            continue
        with _isolated(failed, id(m)):
            verdicts[id(m)] = _verdict(m, features[m.feature_key], reduced, clock, t_patch + t_trunk)
    return verdicts


def _verdict(m: PatchMonitor, features: tuple[Any, Any, float, int], reduced: dict[Any, tuple[Any, float]],
             clock: Callable[[], float], t_shared: float) -> MonitorVerdict:
    """One patch monitor's verdict from the shared features (its reduction shared with monitors of the same key)."""
    feats, mask, t_feat, drawn = features
    rkey = (m.feature_key, m.reduce_key)
    if rkey not in reduced:  # e.g. LHD and the CH taus read the same disc pixels: take them once
        reduced[rkey] = _timed(clock, m.reduce, feats, mask)
    red, t_red = reduced[rkey]
    judgement, t_judge = _timed(clock, m.judge, red)
    seconds = t_shared + share_seconds(t_feat, m.feature_size, drawn) + t_red + t_judge
    return MonitorVerdict(m.name, bool(judgement.accepted), judgement.reason, seconds, float(judgement.score),
                          m.threshold)

