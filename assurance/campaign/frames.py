"""One campaign frame's planning: its pose under the campaign's pose policy, the declared operating domain
(``el.odd``) and the frame gate (``el.monitors.frame_gate``): a frame outside the domain, or above the gate's
threshold, is decided as the flight code decides it, the default action with reason ``outside_odd: ...`` or
``out_of_domain: ...``, while every monitor's verdicts on its candidates stay in the readouts; the gate's score
and threshold are in every image row (``frame_gate_score``, ``frame_gate_threshold``; NaN: no gate)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from assurance.scenes.poses import NOMINAL, frame_pose
from assurance.scenes.uavid import Sample, read_labels
from el.camera import Pose, check_geometry
from el.config import CoreConfig
from el.decision import Candidate
from el.errors import DataError
from el.monitors.frame_gate import FrameGate, judge_frame, load_frame_gate
from el.odd import OperatingDomain

_GATES: dict[tuple[str, str], FrameGate] = {}  # per worker: each gate file read once


def frame_config(config: Any, sample: Sample, size: tuple[int, int]) -> tuple[CoreConfig, dict[str, Any]]:
    """The CM configuration of one frame under the campaign's pose policy, and its pose readouts.

    ValueError (a fault of the task) when the policy requires a pose the frame lacks, or the frame's
    camera, pose and size are outside what the flat-ground model handles (``el.camera.check_geometry``)."""
    pose, roll, source = frame_pose(sample, config.poses, config.core.pose)
    cfg = config.core if source == NOMINAL else replace(config.core, pose=pose)
    try:
        check_geometry(cfg.geometry(*size), roll_deg=roll)
    except ValueError as exc:  # the frame's own pose or size: its data's fault; the nominal pose: the configuration's
        if source == NOMINAL:
            raise
        raise DataError(f"{sample.image_path}: {exc}") from None
    return cfg, {"height_m": float(pose.height_m), "pitch_deg": float(pose.pitch_deg), "roll_deg": float(roll),
                 "pose_source": source}


def frame_truth(sample: Sample, labels: Any, shape: tuple[int, ...]) -> tuple[Any, np.ndarray]:
    """The label set and the frame's ground-truth class ids; DataError (the data's fault) when the frame has no
    label map or one of another size."""
    if sample.label_path is None:
        raise DataError(f"{sample.image_path}: no label map (the campaign needs ground truth)")
    ids = read_labels(sample.label_path, labels=labels)
    if ids.shape != tuple(shape):
        raise DataError(f"{sample.label_path}: label size differs from the image")
    return labels, ids


def outside_odd(odd: dict[str, Any] | None, pose: Pose, size: tuple[int, int]) -> str | None:
    """The ``outside_odd`` reason of a frame under the campaign's declared domain (None: inside, or none declared)."""
    return None if odd is None else OperatingDomain.from_dict(odd).outside(pose, size)


def refuse_outside(image_rows: list[dict[str, Any]], cand_rows: list[dict[str, Any]], reason: str | None) -> None:
    """Rewrite a frame's decisions as the default action for ``reason`` (in place; None: inside, unchanged): no
    candidate selected, the decision's true hazard the default area's. The candidates keep their verdicts."""
    if not reason:
        return
    for row in image_rows:
        row.update(action="default", reason=reason, selected=-1, h_decision=row["h_default"],
                   decision_unsafe=bool(row["h_default"] >= 1.0), clearance_decision_m=math.nan)
    for row in cand_rows:
        row["selected"] = False


def frame_gate(gate: dict[str, str] | None, segmenter: Any) -> FrameGate | None:
    """The campaign's frame gate (read once per worker), refused (ValueError, a fault of the task) when its file
    changed since the run recorded it or it was fitted on another network; turns the segmenter's frame tap on."""
    if not gate:
        return None
    key = (gate["path"], gate["sha256"])
    if key not in _GATES:
        loaded = load_frame_gate(gate["path"])
        if loaded.sha256 != gate["sha256"]:
            raise ValueError(f"{gate['path']}: frame gate changed since the run recorded it (body SHA-256 "
                             f"{loaded.sha256[:12]}..., recorded {gate['sha256'][:12]}...)")
        _GATES[key] = loaded
    _GATES[key].check_network(segmenter)
    segmenter.tap_frames = True
    return _GATES[key]


def gate_readout(gate: FrameGate | None, segmenter: Any) -> tuple[dict[str, float], str | None]:
    """The gate's readout columns of the frame just segmented, and its ``out_of_domain`` reason (None: passed, or
    no gate)."""
    if gate is None:
        return {"frame_gate_score": math.nan, "frame_gate_threshold": math.nan}, None
    info: dict[str, Any] = {}
    reason = judge_frame(gate, segmenter, info)
    return {"frame_gate_score": float(info["frame_gate"]["score"]), "frame_gate_threshold": gate.threshold}, reason


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
