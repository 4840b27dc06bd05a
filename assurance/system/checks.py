"""The checks a system file must pass when it is loaded, before any command starts work.

Beyond the schema (keys, types, ranges): the label set builds, the camera and nominal pose give a valid
geometry at the image size, the model file exists and has the SHA-256 the file states, the class map names
classes that exist, the monitor spec parses, the files it names are regular files (a FIFO or a device is named as
what it is, never read), the perturbations are known, and the frame gate's and calibration card's thresholds lie
where the scores they were fitted on lie (``assurance.system.sense``). Every number is finite (``loader.validate``:
NaN passes a schema's bounds). Loading the model itself (an ONNX file's output shape) is checked when a command
loads it, before any task.
"""

from __future__ import annotations

import os
from collections.abc import Collection
from pathlib import Path

from assurance.perturbations import PERTURBATIONS
from assurance.system import build
from assurance.system.loader import SystemFile
from assurance.system.sense import check_fitted
from el.base.errors import WeightsError
from el.base.hashing import sha256_file
from el.base.userfiles import not_regular
from el.geometry.camera import CameraGeometry
from el.geometry.camera import check_geometry as check_camera_geometry
from el.monitors import parse_monitor_spec
from el.segmentation.onnx_engine import read_onnx


def check_system(system: SystemFile, *, writes: Collection[str] = ()) -> None:
    """Every load-time check; the first problem as ``SystemFileError`` naming the key. ``writes``: keys naming a file
    the command is about to write (``uav-el fit-gate``: ``monitor.gate``), so nothing at their path is no problem."""
    labels = build.label_set(system)
    check_geometry(system)
    check_model(system, labels.names)
    check_monitor(system)
    for key, what in (("monitor.calibration", "calibration card"), ("monitor.gate", "frame gate"),
                      ("waivers.file", "waivers file")):
        p = system.path_of(key)
        why = None if p is None or (key == "monitor.gate" and system.get(key) == "none") else not_regular(p, what=what)
        if why and key in writes and not os.path.lexists(p):
            why = None  # not there yet: the command writes it
        if why:  # nothing there, or what is there instead of a regular file (a FIFO is not "no such file")
            raise system.error(key, why)
    templates = system.path_of("report.templates")
    if templates is not None and not templates.is_dir():
        there = "no such folder" if not templates.exists() else "not a folder"
        raise system.error("report.templates", f"{templates}: {there}")
    perturbations = system.get("targets.required_perturbations")
    if perturbations is not None:
        unknown = [p for p in perturbations if p not in PERTURBATIONS]
        if unknown:
            raise system.error("targets.required_perturbations",
                               f"unknown {unknown[0]!r}; known: {', '.join(PERTURBATIONS)}")
    check_fitted(system, labels)  # the gate's and the card's thresholds where their fits' scores lie


def check_geometry(system: SystemFile) -> None:
    """The camera, nominal pose and image size must give a geometry the flat-ground model handles: every
    reachable row sees the ground at a finite footprint, and some stripe is within reach (``reach_m``): a
    nominal pose with none could never land (every decision the default action)."""
    intr, pose, width_height = build.intrinsics(system), build.nominal_pose(system), build.image_size(system)
    build.safety(system)
    geometry = CameraGeometry(width=width_height[0], height=width_height[1], intrinsics=intr, pose=pose)
    try:
        check_camera_geometry(geometry)
    except ValueError as exc:
        raise system.error("camera", str(exc)) from None
    if geometry.first_reachable_row >= geometry.height:
        nearest = float(geometry.ground_distance(geometry.height - 0.5))
        raise system.error("camera", f"pose height_m {pose.height_m:g}, pitch_deg {pose.pitch_deg:g} with camera "
                                     f"{intr.name!r} on a {width_height[0]}x{width_height[1]} image has no stripe "
                                     f"within the {geometry.reach_m:g} m reach (the nearest ground in view lies "
                                     f"{nearest:.0f} m ahead), so it could never land; raise pitch_deg, lower "
                                     "height_m or widen the field of view")


def check_model(system: SystemFile, names: tuple[str, ...]) -> None:
    """The model section: a consistent kind, an existing file with the stated SHA-256, a class map onto the
    system's classes."""
    kind = build.model_kind(system)
    path = system.path_of("model.path")
    if path is not None:
        why = not_regular(path, what="model file")
        if why:
            raise system.error("model.path", why)
        suffix = {"pt": ".pt", "onnx": ".onnx"}.get(kind)
        if suffix and path.suffix.lower() != suffix:
            raise system.error("model.path", f"{path}: a {kind!r} model is a {suffix} file")
        want = system.get("model.sha256")
        if want is not None:
            have = _identity(system, kind, path) if kind == "onnx" else sha256_file(path)
            if have != want:
                raise system.error("model.sha256", f"{path} has SHA-256 {have}, the system file states {want} "
                                                   "(the file changed, or the wrong file)")
    elif system.get("model.sha256") is not None and kind != "plugin":
        raise system.error("model.sha256", "given without a model file")
    class_map = system.get("model.class_map")
    if class_map:
        unknown = sorted({v for v in class_map.values() if v not in names})
        if unknown:
            raise system.error("model.class_map", f"maps onto {unknown[0]!r}, not a class of the system's label set "
                                                  f"({', '.join(names)})")
    unknown = [u for u in system.get("model.unreachable") or () if u not in names]
    if unknown:
        raise system.error("model.unreachable", f"{unknown[0]!r} is not a class of the system's label set")
    contract = system.get("model.onnx")
    if contract and contract.get("scaling") == "mean_std" and not (contract.get("mean") and contract.get("std")):
        raise system.error("model.onnx", "scaling 'mean_std' needs mean and std")


def _identity(system: SystemFile, kind: str, path: Path) -> str:
    """An ONNX file's identity: its SHA-256, its external data files' included (``el.segmentation.onnx_engine``)."""
    try:
        return read_onnx(path).sha256
    except WeightsError as exc:
        raise system.error("model.path", str(exc)) from None


def check_monitor(system: SystemFile) -> None:
    """The monitor spec parses (a registered or built-in monitor)."""
    spec = system.get("monitor.spec")
    if spec is None:
        return
    try:
        parse_monitor_spec(spec)
    except ValueError as exc:
        raise system.error("monitor.spec", str(exc)) from None
