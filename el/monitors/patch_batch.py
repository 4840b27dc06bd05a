"""Every candidate of one frame judged by a softmax patch monitor, its HD patches segmented in few passes.

``PatchMonitor.check_many`` lands here for monitors whose features rest on the patch's softmax (those that define
``softmax_features``: the learned monitor): the patches are cropped as ``check`` crops them, segmented together
(``predict_patches``: side by side on single-threaded ONNX Runtime sessions, or patches of one padded size in one
batch; each keeps the scores it gets alone, ``el.segmentation.patch_passes``), then each candidate's features,
score and verdict are computed exactly as ``check`` computes them from that softmax, as soon as it is ready (on
the segmenter's worker, when it has them). The frame's softmax, which every candidate's context shares, is
validated once. The decision's deadline is checked before and after the passes, and before each patch's.

Each verdict's ``seconds`` is its own crop plus its share (in proportion to its patch's pixels) of the batched
passes with every candidate's features and judgement, so the walk's monitoring overhead is the time it took.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from el.base.deadline import checkpoint
from el.base.decision import Candidate, Disc, MonitorVerdict
from el.monitors.patches import Patch, accepts_keyword

if TYPE_CHECKING:  # el.monitors.base calls this module: no import back at run time
    from el.monitors.base import CandidateContext, Judgement, PatchMonitor, PatchSegmenter

Validate = Callable[..., Any]
Then = Callable[[int, np.ndarray], Any]


def segment_patches(segmenter: PatchSegmenter, rgbs: list[np.ndarray], then: Then) -> list[Any]:
    """``then(k, softmax)`` of each patch k: the softmax from one ``predict_patches`` call when the segmenter has
    it (given ``then`` when it takes it: a segmenter that runs patches side by side runs ``then`` there too),
    else from one ``predict_patch`` per patch (any ``PatchSegmenter``)."""
    batched = getattr(segmenter, "predict_patches", None)
    if not callable(batched) or not rgbs:
        return [then(k, segmenter.predict_patch(rgb)) for k, rgb in enumerate(rgbs)]
    if accepts_keyword(batched, "then"):
        out = list(batched(rgbs, then=then))
    else:
        out = list(batched(rgbs))
        out = [then(k, probs) for k, probs in enumerate(out)] if len(out) == len(rgbs) else out
    if len(out) != len(rgbs):
        raise ValueError(f"predict_patches returned {len(out)} results for {len(rgbs)} patches")
    return out


def checked_contexts(contexts: Sequence[CandidateContext | None], monitor: PatchMonitor, validate: Validate
                     ) -> list[CandidateContext | None]:
    """The contexts with each distinct frame softmax validated once by ``validate`` (``validate_scores``) and
    marked ``frame_checked``, as the per-candidate features would validate it for every candidate."""
    labels = getattr(monitor, "labels", None)
    checked: set[int] = set()
    out: list[CandidateContext | None] = []
    for ctx in contexts:
        if ctx is None or ctx.frame_checked:
            out.append(ctx)
            continue
        frame = ctx.frame_probs
        if id(frame) not in checked and _valid_frame(frame, labels, validate):
            checked.add(id(frame))
        out.append(dataclasses.replace(ctx, frame_checked=True) if id(frame) in checked else ctx)
    return out


def _valid_frame(frame: object, labels: Any, validate: Validate) -> bool:
    """Whether ``frame`` passes ``validate`` (a frame that fails stays unchecked: the candidate's own check then
    raises its usual error)."""
    if not isinstance(frame, np.ndarray) or frame.ndim != 3:
        return False
    try:
        validate(frame, frame.shape[1:], "frame softmax", labels=labels)
    except ValueError:
        return False
    return True


def _timed(clock: Callable[[], float], fn: Callable[..., Any], *args: Any) -> tuple[Any, float]:
    t = clock()
    out = fn(*args)
    return out, clock() - t


def pass_shares(patches: Sequence[Patch], seconds: float) -> list[float]:
    """``seconds`` of batched passes shared among the patches in proportion to their pixels."""
    pixels = np.array([p.rgb.shape[0] * p.rgb.shape[1] for p in patches], dtype=np.float64)
    total = float(pixels.sum())
    return [seconds * float(px) / total for px in pixels] if total > 0 else [0.0] * len(patches)


def check_batched(monitor: PatchMonitor, hd_image: np.ndarray, candidates: Sequence[Candidate | Disc],
                  segmenter: PatchSegmenter, *, seeds: Sequence[int], contexts: Sequence[CandidateContext | None],
                  validate: Validate) -> list[MonitorVerdict]:
    """``monitor.check`` on every candidate (seed ``seeds[k]``, context ``contexts[k]``), the patches'
    softmax computed in batched passes, each candidate's features and judgement as soon as its softmax is ready
    (on the segmenter's workers, when it has them); raises as ``check`` would. ``validate``: the scores check
    (``el.monitors.base.validate_scores``) the frame softmax passes once."""
    clock = monitor.clock
    checkpoint("monitoring")
    cropped = [_timed(clock, monitor.patch, hd_image, c) for c in candidates]
    patches = [p for p, _ in cropped]
    contexts = checked_contexts(contexts, monitor, validate)

    def judge(k: int, probs: np.ndarray) -> Judgement:
        features, mask = monitor.softmax_features(probs, patches[k], segmenter, seed=int(seeds[k]),
                                                  context=contexts[k])
        return monitor.judge(monitor.reduce(features, mask))

    judgements, seconds = _timed(clock, segment_patches, segmenter, [p.rgb for p in patches], judge)
    checkpoint("monitoring")
    shares = pass_shares(patches, seconds)
    return [monitor._verdict(j, cropped[k][1] + shares[k]) for k, j in enumerate(judgements)]
