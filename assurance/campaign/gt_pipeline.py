"""The ground-truth pipeline: a label map -> the CM -> a landing decision, without a model or monitor.

It answers "what would the EL system decide if the segmentation were perfect?": the structural
check of EL-R01 on whole scenes, and the reference for the model pipeline. The full-resolution
label map is pooled conservatively to the working resolution (``el.core.probs_from_labels``), the
CM ranks the candidates, and the decision is to land on rank 0 (no runtime monitor: every
candidate's ``monitor`` is None), or the default action when there is no candidate. A fault inside
the CM ends in the default action with reason ``"fault: ..."`` (EL-R06).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from assurance.scenes.poses import NOMINAL, frame_pose
from assurance.scenes.uavid import DataError, Sample, check_same_size, read_labels
from el.camera import Pose, check_geometry, working_size
from el.config import CoreConfig
from el.core import default_area, probs_from_labels, run_core
from el.decision import Decision, decision_schema  # noqa: F401  (re-exported)
from el.hashing import sha256_file
from el.labels import UAVID, LabelSet
from el.odd import OperatingDomain
from el.pipeline import frame_core, pose_record
from el.walk import walk_candidates

PIPELINE = "ground_truth"
logger = logging.getLogger(__name__)  # faults with their tracebacks; the decision keeps only the reason


def _check_ids(ids: np.ndarray, labels: LabelSet = UAVID) -> tuple[int, int]:
    ids = np.asarray(ids)
    if ids.ndim != 2 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"label map must be a 2-D array of integer class ids, got {ids.dtype} {ids.shape}")
    h, w = ids.shape
    if w < 8 or h < 8:
        raise ValueError(f"label map must be at least 8x8, got {w}x{h}")
    if ids.min() < 0 or ids.max() >= labels.num_classes:
        raise ValueError(f"class ids must lie in 0..{labels.num_classes - 1}, got {ids.min()}..{ids.max()}")
    return w, h


def decide_from_labels(
    ids: np.ndarray,
    *,
    config: CoreConfig | None = None,
    input_info: dict[str, Any] | None = None,
    read_s: float = 0.0,
    clock: Callable[[], float] = time.perf_counter,
    labels: LabelSet = UAVID,
    pose: Pose | None = None,
    roll_deg: float = 0.0,
    odd: OperatingDomain | None = None,
) -> Decision:
    """The decision for a full-resolution class-id map (H, W) under a perfect segmentation.

    ``input_info`` goes to the decision's ``"input"`` (path, sha256; width and height are filled
    in). ``read_s`` is the time already spent reading the input. ``labels``: the label set of the
    ids (default UAVid). ``pose`` (and ``roll_deg``): the frame's pose, as ``el.pipeline``'s; None is
    ``config.pose``. ValueError for a malformed map; a pose the flat-ground model cannot plan with
    (``el.camera.check_geometry``) gives the default action with reason ``"fault: pose: <error>"``,
    a failure inside the CM with ``"fault: <error>"``. ``odd``: the declared operating domain; a pose or size
    outside it is the default action with reason ``outside_odd: ...``, as the flight pipeline decides it.
    """
    config = config or CoreConfig()
    ids = labels.planning_ids(ids)  # unknown (ignored) ground is never a landing site: planned as forbidden
    W, H = _check_ids(ids, labels)
    t0 = clock()
    info = dict(input_info or {})
    info.update(width=W, height=H)
    timings = {"read_s": float(read_s), "segmentation_s": 0.0, "candidates_s": 0.0, "monitoring_s": 0.0}
    nominal = config
    try:
        config = frame_core(config, pose)
        info["pose"] = pose_record(config.pose, nominal=pose is None)
        if roll_deg:
            info["pose"]["roll_deg"] = float(roll_deg)  # not modelled: a pose error within MAX_ROLL_DEG
        outside = None if odd is None else odd.outside(config.pose, (W, H))
        if not outside:  # outside the domain: refused before planning, as el.pipeline does
            check_geometry(config.geometry(W, H), roll_deg=roll_deg)
    except Exception as exc:  # fail safe, as the flight pipeline: the default action, with the reason
        cfg = {"pipeline": PIPELINE, "monitor": None, "core": nominal.to_dict()}
        timings["total_s"] = float(read_s) + clock() - t0
        return Decision(action="default", reason=f"fault: pose: {type(exc).__name__}: {exc}", selected=None,
                        candidates=[], default_area=default_area(W, H, nominal), timings=timings, input=info,
                        config=cfg)
    cfg = {"pipeline": PIPELINE, "monitor": None, "core": config.to_dict(),
           **({"odd": odd.to_dict()} if odd is not None else {})}
    area = default_area(W, H, config)
    if outside:  # no evidence of safety there: the default action, a decision and not a fault
        timings["total_s"] = float(read_s) + clock() - t0
        return Decision(action="default", reason=outside, selected=None, candidates=[], default_area=area,
                        timings=timings, input=info, config=cfg)
    try:
        probs = probs_from_labels(ids, working_size(W, H, config.working_width), labels=labels)
        t1 = clock()
        core = run_core(probs, (W, H), config, clock=clock, labels=labels)
        t2 = clock()
    except Exception as exc:  # fail safe: any fault ends in the default action, with its reason
        logger.exception("fault in the core model on %s; default action", info.get("path", "?"))
        timings["total_s"] = float(read_s) + clock() - t0
        return Decision(action="default", reason=f"fault: {type(exc).__name__}: {exc}", selected=None,
                        candidates=[], default_area=area, timings=timings, input=info, config=cfg)
    timings["segmentation_s"] = t1 - t0
    timings["candidates_s"] = t2 - t1
    timings.update({k: v for k, v in core.timings.items() if k != "total_s"})
    timings["total_s"] = float(read_s) + clock() - t0
    outcome = walk_candidates(len(core.candidates), None)  # no monitor: the top candidate, as the pipeline
    return Decision(action=outcome.action, reason=outcome.reason, selected=outcome.selected,
                    candidates=core.candidates, default_area=area, timings=timings, input=info, config=cfg)


def decide_from_label_file(
    labels_path: str | Path,
    *,
    image_path: str | Path | None = None,
    config: CoreConfig | None = None,
    labels: LabelSet = UAVID,
    pose: Pose | None = None,
    roll_deg: float = 0.0,
    odd: OperatingDomain | None = None,
) -> tuple[Decision, np.ndarray]:
    """Read a colour label PNG (``labels``' palette, UAVid by default) and decide; returns (decision, class ids).

    The optional image is only checked for size (it is for drawing) and identified in
    ``input["image"]``; ``odd`` as :func:`decide_from_labels`. DataError (from ``assurance.scenes.uavid``) for a
    missing, unreadable or inconsistent file.
    """
    labels_path = Path(labels_path)
    t0 = time.perf_counter()
    ids = read_labels(labels_path, labels)
    info: dict[str, Any] = {"path": str(labels_path), "sha256": sha256_file(labels_path), "kind": "labels"}
    if image_path is not None:
        image_path = Path(image_path)
        if not image_path.is_file():
            raise DataError(f"{image_path}: no such file")
        check_same_size(image_path, labels_path)
        info["image"] = {"path": str(image_path), "sha256": sha256_file(image_path)}
    read_s = time.perf_counter() - t0
    return decide_from_labels(ids, config=config, input_info=info, read_s=read_s, labels=labels, pose=pose,
                              roll_deg=roll_deg, odd=odd), ids


def decide_sample(sample: Sample, *, config: CoreConfig | None = None, poses: str = "nominal",
                  labels: LabelSet = UAVID) -> Decision:
    """The ground-truth decision for a UAVid-layout sample, planned at its pose under the policy ``poses``
    (``assurance.scenes.poses``; read the samples with ``iter_samples(..., poses=True)``). A frame
    without the pose the policy requires is the default action with reason ``"fault: pose: ..."``."""
    config = config or CoreConfig()
    if sample.label_path is None:
        raise DataError(f"{sample.image_path}: no label map (the ground-truth pipeline needs one)")
    try:
        pose, roll, source = frame_pose(sample, poses, config.pose)
    except DataError as exc:
        ids = labels.planning_ids(read_labels(sample.label_path, labels))
        W, H = _check_ids(ids, labels)
        info = {"path": str(sample.label_path), "kind": "labels", "width": W, "height": H}
        return Decision(action="default", reason=f"fault: pose: {type(exc).__name__}: {exc}", selected=None,
                        candidates=[], default_area=default_area(W, H, config), timings={}, input=info,
                        config={"pipeline": PIPELINE, "monitor": None, "core": config.to_dict()})
    decision, _ = decide_from_label_file(sample.label_path, config=config, labels=labels,
                                         pose=None if source == NOMINAL else pose, roll_deg=roll)
    return decision

