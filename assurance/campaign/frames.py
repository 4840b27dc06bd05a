"""One campaign frame's planning: its pose under the campaign's pose policy, and the declared operating domain
(``el.odd``): a frame outside it is decided as the flight code decides it, the default action with reason
``outside_odd: ...``, while every monitor's verdicts on its candidates stay in the readouts."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from assurance.scenes.poses import NOMINAL, frame_pose
from assurance.scenes.uavid import Sample
from el.camera import Pose, check_geometry
from el.config import CoreConfig
from el.errors import DataError
from el.odd import OperatingDomain


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
