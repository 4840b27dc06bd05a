"""What a campaign task adds around the flight kernel (``el.flight.kernel``) for one frame: its pose under the
campaign's pose
policy (the frame's own pose is its data's fault when unplannable), its ground truth, the frame gate read once per
worker, and the gate's readout columns (``frame_gate_score``, ``frame_gate_threshold``; NaN: no gate). The declared
domain and the gate decide the frame inside the kernel, as in flight."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from assurance.campaign.frame_cache import cached, file_key
from assurance.dataio.layouts import read_sample_labels
from assurance.dataio.poses import NOMINAL, frame_pose
from assurance.dataio.uavid import Sample
from el.base.decision import Candidate
from el.base.errors import DataError
from el.geometry.camera import Pose, check_geometry
from el.monitors.frame_gate import FrameGate, GateFile

_GATES: dict[tuple[str, str], FrameGate] = {}  # per worker: each gate file read once


def frame_pose_of(config: Any, sample: Sample) -> tuple[Pose | None, float, dict[str, Any]]:
    """The pose that plans a campaign frame under the campaign's pose policy (None: the nominal one), its roll, and
    its pose readouts. DataError (the data's fault) when the policy requires a pose the frame lacks."""
    pose, roll, source = frame_pose(sample, config.poses, config.core.pose)
    cols = {"height_m": float(pose.height_m), "pitch_deg": float(pose.pitch_deg), "roll_deg": float(roll),
            "pose_source": source}
    return (None if source == NOMINAL else pose), roll, cols


def check_frame_pose(config: Any, sample: Sample, pose: Pose | None, roll: float, size: tuple[int, int]) -> None:
    """Refuse a frame whose camera, pose and size are outside what the flat-ground model handles
    (``el.geometry.camera.check_geometry``): the frame's own pose is its data's fault (DataError), the nominal pose the
    configuration's (ValueError)."""
    cfg = config.core if pose is None else replace(config.core, pose=pose)
    try:
        check_geometry(cfg.geometry(*size), roll_deg=roll)
    except ValueError as exc:
        if pose is None:
            raise
        raise DataError(f"{sample.image_path}: {exc}") from None


def frame_truth(sample: Sample, labels: Any, shape: tuple[int, ...]) -> tuple[Any, np.ndarray]:
    """The label set and the frame's ground-truth class ids; DataError (the data's fault) when the frame has no
    label map or one of another size."""
    if sample.label_path is None:
        raise DataError(f"{sample.image_path}: no label map (the campaign needs ground truth)")
    key = file_key(sample.label_path, labels, sample.label_encoding, sample.id_offset)
    ids = cached("labels", key, lambda: read_sample_labels(sample, labels))
    if ids.shape != tuple(shape):
        raise DataError(f"{sample.label_path}: label size {ids.shape[1]}x{ids.shape[0]} differs from image "
                        f"{sample.image_path} ({shape[1]}x{shape[0]}, as read: EXIF orientation applied)")
    return labels, ids


def frame_gate(gate: GateFile | None, segmenter: Any) -> FrameGate | None:
    """The campaign's frame gate (read once per worker), refused (ValueError, a fault of the task) when its file
    changed since the run recorded it or it was fitted on another network (``el.flight.kernel.build_parts`` binds
    it)."""
    if gate is None:
        return None
    key = (gate.path, gate.sha256)
    if key not in _GATES:
        _GATES[key] = gate.load()
    _GATES[key].check_network(segmenter)
    return _GATES[key]


def gate_columns(gate: FrameGate | None, info: dict[str, Any]) -> dict[str, float]:
    """The gate's readout columns of a frame, from the kernel's ``input.frame_gate`` record (NaN: no gate, or the
    frame was not scored)."""
    record = info.get("frame_gate") or {}
    score = record.get("score")
    return {"frame_gate_score": math.nan if gate is None or score is None else float(score),
            "frame_gate_threshold": math.nan if gate is None else gate.threshold}


def clearance_of(fn: Callable[..., Any] | None, sample: Sample, size: tuple[int, int],
                 cands: Sequence[Candidate]) -> list[float]:
    """Metric clearance (m) of each candidate's centre from the scene's world model, NaN without one."""
    if fn is None or not cands:
        return [float("nan")] * len(cands)
    try:
        vals = fn(sample, size, np.array([c.x for c in cands]), np.array([c.y for c in cands]))
        return [float(v) for v in vals]
    except Exception:  # no meta or no world model: the readout says NaN
        return [float("nan")] * len(cands)
