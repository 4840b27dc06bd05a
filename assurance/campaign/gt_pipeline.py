"""The ground-truth pipeline: a label map -> the CM -> a landing decision, without a model or monitor.

It answers "what would the EL system decide if the segmentation were perfect?": the structural
check of EL-R01 on whole scenes, and the reference for the model pipeline. It is the flight kernel
(``el.flight.kernel``) with a label-map segmenter: the full-resolution label map is pooled conservatively to the
working resolution (``el.landing.core.probs_from_labels``), the CM ranks the candidates, and the decision is to land on
rank 0 (no runtime monitor: every candidate's ``monitor`` is None), or the default action when there is no
candidate. A fault inside the CM ends in the default action with reason ``"fault: ..."`` (EL-R06).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from assurance.dataio.layouts import read_label_file, read_sample_labels
from assurance.dataio.poses import NOMINAL, frame_pose
from assurance.dataio.uavid import DataError, Sample, check_same_size
from el.base.decision import Decision, decision_schema  # noqa: F401  (re-exported)
from el.base.hashing import sha256_file
from el.classes.labels import LabelSet
from el.flight.kernel import FramePose, build_parts, decide_frame
from el.geometry.camera import working_size
from el.geometry.config import CoreConfig
from el.geometry.odd import OperatingDomain
from el.landing.core import default_area, probs_from_labels

PIPELINE = "ground_truth"
logger = logging.getLogger(__name__)  # faults with their tracebacks; the decision keeps only the reason


def _check_ids(ids: np.ndarray, labels: LabelSet) -> tuple[int, int]:
    ids = np.asarray(ids)
    if ids.ndim != 2 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"label map must be a 2-D array of integer class ids, got {ids.dtype} {ids.shape}")
    h, w = ids.shape
    if w < 8 or h < 8:
        raise ValueError(f"label map must be at least 8x8, got {w}x{h}")
    if ids.min() < 0 or ids.max() >= labels.num_classes:
        raise ValueError(f"class ids must lie in 0..{labels.num_classes - 1}, got {ids.min()}..{ids.max()}")
    return w, h


class LabelMapSegmenter:
    """A perfect segmentation: the frame's class ids pooled conservatively to the working resolution
    (``el.landing.core.probs_from_labels``), whatever array the kernel hands it (the ids themselves)."""

    def __init__(self, ids: np.ndarray, labels: LabelSet, working_width: int) -> None:
        self.ids, self.labels, self.working_width = ids, labels, working_width

    def predict_frame(self, frame: np.ndarray) -> np.ndarray:
        H, W = self.ids.shape
        return probs_from_labels(self.ids, working_size(W, H, self.working_width), labels=self.labels)


def decide_from_labels(
    ids: np.ndarray,
    *,
    config: CoreConfig | None = None,
    input_info: dict[str, Any] | None = None,
    read_s: float = 0.0,
    clock: Callable[[], float] = time.perf_counter,
    labels: LabelSet,
    pose: FramePose | None = None,
    odd: OperatingDomain | None = None,
) -> Decision:
    """The decision for a full-resolution class-id map (H, W) under a perfect segmentation: the flight kernel
    (``el.flight.kernel``) with a label-map segmenter and no monitor.

    ``input_info`` goes to the decision's ``"input"`` (path, sha256; width and height are filled
    in). ``read_s`` is the time already spent reading the input. ``labels``: the label set of the
    ids (the system's). ``pose``: the frame's pose, where it came from and its roll
    (``el.flight.kernel.FramePose``), as ``el.flight.pipeline``'s; None is ``config.pose``. ValueError for a
    malformed map; a pose the flat-ground model cannot plan with (``el.geometry.camera.check_geometry``) gives the
    default action with reason ``"fault: pose: <error>"``, a failure inside the CM
    ``"fault: candidates: <error>"``. ``odd``: the declared operating domain; a pose or
    size outside it is the default action with reason ``outside_odd: ...``, as the flight pipeline decides it.
    """
    config = config or CoreConfig()
    ids = labels.planning_ids(ids)  # unknown (ignored) ground is never a landing site: planned as forbidden
    W, H = _check_ids(ids, labels)
    record = {"pipeline": PIPELINE, "monitor": None, "core": config.to_dict(),
              **({"odd": odd.to_dict()} if odd is not None else {})}
    parts = build_parts(LabelMapSegmenter(ids, labels, config.working_width), config, labels=labels, odd=odd,
                        record=record, nominal_size=(W, H))

    def read(info: dict[str, Any]) -> np.ndarray:
        info.update(input_info or {})
        info.update(width=W, height=H)
        del info["frame_gate"]  # no frame gate on a label map
        return ids

    decision = decide_frame(read, parts, None, pose=pose, clock=clock)
    decision.timings["read_s"] = float(read_s)
    decision.timings["total_s"] += float(read_s)
    return decision


def decide_from_label_file(
    labels_path: str | Path,
    *,
    image_path: str | Path | None = None,
    config: CoreConfig | None = None,
    labels: LabelSet,
    pose: FramePose | None = None,
    odd: OperatingDomain | None = None,
    encoding: str = "rgb",
    id_offset: int = 0,
) -> tuple[Decision, np.ndarray]:
    """Read a colour label PNG (``labels``' palette) and decide; returns (decision, class ids).

    The optional image is only checked for size (it is for drawing) and identified in
    ``input["image"]``; ``pose`` and ``odd`` as :func:`decide_from_labels`; ``encoding`` and
    ``id_offset`` how the file codes classes (``assurance.dataio.layouts.read_label_file``). DataError (from
    ``assurance.dataio.uavid``) for a
    missing, unreadable or inconsistent file.
    """
    labels_path = Path(labels_path)
    t0 = time.perf_counter()
    ids = read_label_file(labels_path, labels, encoding=encoding, id_offset=id_offset)
    info: dict[str, Any] = {"path": str(labels_path), "sha256": sha256_file(labels_path), "kind": "labels"}
    if image_path is not None:
        image_path = Path(image_path)
        if not image_path.is_file():
            raise DataError(f"{image_path}: no such file")
        check_same_size(image_path, labels_path)
        info["image"] = {"path": str(image_path), "sha256": sha256_file(image_path)}
    read_s = time.perf_counter() - t0
    return decide_from_labels(ids, config=config, input_info=info, read_s=read_s, labels=labels, pose=pose,
                              odd=odd), ids


def decide_sample(sample: Sample, *, labels: LabelSet, config: CoreConfig | None = None,
                  poses: str = "nominal") -> Decision:
    """The ground-truth decision for a UAVid-layout sample, planned at its pose under the policy ``poses``
    (``assurance.dataio.poses``; read the samples with ``iter_samples(..., poses=True)``). A frame
    without the pose the policy requires is the default action with reason ``"fault: pose: ..."``."""
    config = config or CoreConfig()
    if sample.label_path is None:
        raise DataError(f"{sample.image_path}: no label map (the ground-truth pipeline needs one)")
    try:
        pose, roll, source = frame_pose(sample, poses, config.pose)
    except DataError as exc:
        ids = labels.planning_ids(read_sample_labels(sample, labels))
        W, H = _check_ids(ids, labels)
        info = {"path": str(sample.label_path), "kind": "labels", "width": W, "height": H}
        return Decision(action="default", reason=f"fault: pose: {type(exc).__name__}: {exc}", selected=None,
                        candidates=[], default_area=default_area(W, H, config), timings={}, input=info,
                        config={"pipeline": PIPELINE, "monitor": None, "core": config.to_dict()})
    decision, _ = decide_from_label_file(sample.label_path, config=config, labels=labels,
                                         pose=FramePose(None if source == NOMINAL else pose, roll_deg=roll),
                                         encoding=sample.label_encoding, id_offset=sample.id_offset)
    return decision

