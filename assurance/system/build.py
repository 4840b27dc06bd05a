"""Turn a system file's settings into the objects the flight code and the harness take: label set, camera,
core configuration, model, monitor, data roots, requirement targets, waivers, report settings.

Each function reads one section; a command-line option given explicitly wins over the file (the caller passes
it). Errors name the system file and the key (``SystemFileError``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from assurance.dataio.layouts import DataSpec
from assurance.perturbations import PERTURBATIONS
from el.classes.labels import UAVID, LabelSet, load_label_set
from el.geometry.camera import CAMERAS, Intrinsics, Pose, SafetyParams
from el.geometry.config import CoreConfig
from el.geometry.odd import OperatingDomain
from el.monitors.calibration import CalibrationError, check_card_spec, load_calibration
from el.segmentation.onnx_model import OnnxContract

if TYPE_CHECKING:  # only named in annotations: loader's SystemFile reads its sections through this module
    from assurance.system.loader import SystemFile

DEFAULT_IMAGE_SIZE = (3840, 2160)
MODEL_KINDS = ("builtin", "pt", "onnx", "plugin")


def label_set(system: SystemFile) -> LabelSet:
    """The system's label set: ``[labels] preset`` or ``file`` (with ``ignore_rgb`` when given)."""
    if "labels" in system._cache:
        return system._cache["labels"]
    preset, file = system.get("labels.preset"), system.path_of("labels.file")
    if preset is not None and file is not None:
        raise system.error("labels", "give either preset or file, not both")
    try:
        if file is not None:
            labels = load_label_set(file)
        elif preset in (None, "uavid"):
            labels = UAVID
        else:
            labels = load_label_set(preset)
    except (ValueError, OSError) as exc:
        key = "labels.file" if file is not None else "labels.preset"
        raise system.error(key, str(exc)) from None
    ignore = system.get("labels.ignore_rgb")
    if ignore is not None:
        labels = _with_ignore(system, labels, tuple(ignore))
    system._cache["labels"] = labels
    return labels


def _with_ignore(system: SystemFile, labels: LabelSet, rgb: tuple[int, ...]) -> LabelSet:
    if not hasattr(labels, "with_ignore"):
        raise system.error("labels.ignore_rgb", "this version of the label set has no ignore colour")
    try:
        return labels.with_ignore(rgb)
    except ValueError as exc:
        raise system.error("labels.ignore_rgb", str(exc)) from None


def intrinsics(system: SystemFile) -> Intrinsics:
    """The camera's lens and sensor: ``preset``, overridden by ``sensor_width_mm`` and ``focal_mm`` or
    ``hfov_deg``."""
    preset = system.get("camera.preset", "phantom4")
    if preset not in CAMERAS:
        raise system.error("camera.preset", f"{preset!r} is not a known camera; known: {', '.join(sorted(CAMERAS))} "
                                            "(or give sensor_width_mm and focal_mm or hfov_deg)")
    base = CAMERAS[preset]
    if system.sets("camera.focal_mm") and system.sets("camera.hfov_deg"):
        raise system.error("camera", "give focal_mm or hfov_deg, not both")
    width = float(system.get("camera.sensor_width_mm", base.sensor_width_mm))
    focal = float(system.get("camera.focal_mm", base.focal_mm))
    if system.get("camera.hfov_deg") is not None:
        focal = width / (2.0 * math.tan(math.radians(float(system.get("camera.hfov_deg"))) / 2.0))
    name = system.get("camera.name") or (
        f"custom (sensor {width:g} mm, focal {focal:.3g} mm)" if _custom_lens(system) else base.name)
    kwargs: dict[str, Any] = {"sensor_width_mm": width, "focal_mm": focal, "name": str(name)}
    if system.get("camera.sensor_height_mm") is not None:
        kwargs["sensor_height_mm"] = float(system.get("camera.sensor_height_mm"))
    try:
        return Intrinsics(**kwargs)
    except ValueError as exc:
        raise system.error("camera", str(exc)) from None


def _custom_lens(system: SystemFile) -> bool:
    """Whether the file sets the lens or sensor itself (not only a preset)."""
    return any(system.sets(f"camera.{k}") for k in ("sensor_width_mm", "focal_mm", "hfov_deg"))


def camera_named(system: SystemFile) -> bool:
    """Whether the camera's name is declared: ``camera.name``, or a preset's own name for the preset's own lens (a
    custom lens without a name is named for what it is, ``custom (sensor W mm, focal F mm)``, by :func:`intrinsics`)."""
    return system.get("camera.name") is not None or not _custom_lens(system)


def nominal_pose(system: SystemFile) -> Pose:
    """The nominal pose (``camera.height_m``, ``camera.pitch_deg``)."""
    try:
        return Pose(height_m=float(system.get("camera.height_m", 50.0)),
                    pitch_deg=float(system.get("camera.pitch_deg", 45.0)))
    except ValueError as exc:
        raise system.error("camera", str(exc)) from None


def safety(system: SystemFile) -> SafetyParams:
    """The safety radius R and its coefficient beta (``[safety]``)."""
    try:
        return SafetyParams(radius_m=float(system.get("safety.radius_m", 2.0)),
                            beta=float(system.get("safety.beta", 1.7)))
    except ValueError as exc:
        raise system.error("safety", str(exc)) from None


def image_size(system: SystemFile) -> tuple[int, int]:
    """The camera's image size (``camera.image_width`` x ``camera.image_height``; 3840x2160 by default)."""
    return (int(system.get("camera.image_width", DEFAULT_IMAGE_SIZE[0])),
            int(system.get("camera.image_height", DEFAULT_IMAGE_SIZE[1])))


def core_config(system: SystemFile, **overrides: Any) -> CoreConfig:
    """The core model's configuration of this system (camera, nominal pose, safety); ``overrides`` (non-None)
    win, e.g. a command-line ``--mode``."""
    kwargs: dict[str, Any] = {"intrinsics": intrinsics(system), "pose": nominal_pose(system),
                              "safety": safety(system)}
    width = system.get("model.working_width")
    if width is not None:
        kwargs["working_width"] = int(width)
    reach = system.get("safety.reach_m")
    if reach is not None:
        kwargs["reach_m"] = float(reach)
    kwargs.update({k: v for k, v in overrides.items() if v is not None})
    return CoreConfig(**kwargs)


ODD_POSE_ERROR = 0.2  # a moved camera without its own [odd] range: its nominal pose +- this fraction


def odd(system: SystemFile) -> OperatingDomain:
    """The declared operating domain (``[odd]``). A file that moves the nominal pose (``camera.height_m`` or
    ``pitch_deg``) without declaring that range gets its nominal value +-20% (the registry's pose error), and
    one that sets the camera's image size without declaring the image ranges gets that size exactly and that
    aspect +-5%: the embedded default's ranges describe the shipped camera, not another."""
    values = {k: system.get(f"odd.{k}") for k in ("height_m", "pitch_deg", "image_width", "image_height", "aspect")}
    pose = nominal_pose(system)
    for key, nominal in (("height_m", pose.height_m), ("pitch_deg", pose.pitch_deg)):
        if system.sets(f"camera.{key}") and not system.sets(f"odd.{key}"):
            values[key] = [round(nominal * (1 - ODD_POSE_ERROR), 6), round(nominal * (1 + ODD_POSE_ERROR), 6)]
    if system.sets("camera.image_width") or system.sets("camera.image_height"):
        width, height = image_size(system)
        for key, value in (("image_width", width), ("image_height", height)):
            if not system.sets(f"odd.{key}"):
                values[key] = [value, value]
        if not system.sets("odd.aspect"):
            values["aspect"] = [round(width / height / 1.05, 6), round(width / height * 1.05, 6)]
    perturbations = dict(system.get("odd.perturbations") or {})
    unknown = sorted(set(perturbations) - set(PERTURBATIONS))
    if unknown:
        raise system.error("odd.perturbations", f"unknown perturbation(s) {', '.join(unknown)}; known: "
                                                f"{', '.join(PERTURBATIONS)}")
    try:
        return OperatingDomain(**values, perturbations=perturbations)
    except (TypeError, ValueError) as exc:
        raise system.error("odd", str(exc)) from None


def poses_policy(system: SystemFile) -> str:
    """How per-frame poses are used: ``nominal``, ``sidecar`` (a frame's own pose when it has one) or
    ``required`` (a frame without one is a fault)."""
    return str(system.get("camera.poses", "nominal"))


def model_kind(system: SystemFile) -> str:
    """``builtin``, ``pt``, ``onnx`` or ``plugin``: ``[model] kind``, else inferred from ``path``/``name``."""
    kind = system.get("model.kind")
    path, name = system.get("model.path"), system.get("model.name")
    if kind is None and path and name:
        raise system.error("model", "give path (a .pt or .onnx file) or name (a plugin), not both")
    if kind is None:
        kind = "plugin" if name else "onnx" if str(path or "").lower().endswith(".onnx") else "pt" if path else \
            "builtin"
    if kind in ("pt", "onnx") and not path:
        raise system.error("model.path", f"kind {kind!r} needs the model file's path")
    if kind == "plugin" and not name:
        raise system.error("model.name", "kind 'plugin' needs the name registered in the uav_el.models entry points")
    if kind == "builtin" and (path or name):
        raise system.error("model", "kind 'builtin' (the shipped network) takes no path or name")
    _check_model_keys(system, str(kind))
    return str(kind)


def _check_model_keys(system: SystemFile, kind: str) -> None:
    """A ``[model]`` key that means nothing for the model's kind is refused, never ignored; the output channels'
    names (``classes``, ``onnx.class_names``) agree and an ONNX contract is well formed."""
    if kind == "plugin" and system.get("model.path") is not None:
        raise system.error("model.path", "kind 'plugin' takes no path: its name (NAME or NAME:ARG) says what it loads")
    if kind in ("pt", "onnx") and system.get("model.name") is not None:
        raise system.error("model.name", f"a {kind!r} model is its file (path); name is for kind 'plugin'")
    if system.get("model.onnx") is not None and kind != "onnx":
        raise system.error("model.onnx", f"an ONNX contract given for a {kind!r} model")
    if system.get("model.unreachable") and not system.get("model.class_map"):
        raise system.error("model.unreachable", "only with a class_map (the system classes no network class maps "
                                                "onto)")
    classes = system.get("model.classes")
    if kind == "builtin" and classes is not None and list(classes) != list(UAVID.names):
        raise system.error("model.classes", f"the shipped network's output channels are {', '.join(UAVID.names)}, "
                                            "in this order")
    contract = system.get("model.onnx")
    if contract is None:
        return
    names = contract.get("class_names")
    if names is None and classes is None:
        raise system.error("model.onnx.class_names", "missing: the output channels' class names, in channel order "
                                                     "(here or as [model] classes)")
    if names is not None and classes is not None and list(names) != list(classes):
        raise system.error("model.classes", f"{list(classes)} differs from [model.onnx] class_names {list(names)}")
    try:
        OnnxContract.from_dict({**contract, "class_names": names or classes})
    except (TypeError, ValueError) as exc:
        raise system.error("model.onnx", str(exc)) from None


def model_source(system: SystemFile) -> dict[str, Any]:
    """The model as data (picklable, recorded in manifests): kind, resolved path, name, expected identity
    (SHA-256), ONNX contract, class map, the system's label set it must produce, and, when the file sets them,
    the output channels' names (``classes``) and the working width."""
    kind = model_kind(system)
    path = system.path_of("model.path")
    source = {"kind": kind, "path": None if path is None else str(path.resolve()), "name": system.get("model.name"),
              "sha256": system.get("model.sha256"), "onnx": system.get("model.onnx"),
              "class_map": system.get("model.class_map"), "unreachable": system.get("model.unreachable") or [],
              "labels": label_set(system).to_dict(),
              "system": system.label}
    for key in ("classes", "working_width"):  # only when set: a source without them records as before
        if system.get(f"model.{key}") is not None:
            source[key] = system.get(f"model.{key}")
    return source


def monitor_spec(system: SystemFile) -> str | None:
    """The deployed monitor's spec (``[monitor] spec``; the shipped one by default)."""
    from el.flight.pipeline import DEPLOYED_MONITOR  # deferred: pulls in scipy; keeps the commands' --help light

    return str(system.get("monitor.spec", DEPLOYED_MONITOR))


def deployed_card(system: SystemFile) -> Path | None:
    """The calibration card of the deployed monitor: ``[monitor] calibration`` when the file also names the
    monitor, the shipped card when it names neither (the shipped pair), else None (a system naming only a card
    deploys the card's own spec; one naming only a monitor has no card, as in :func:`targets`)."""
    from el.flight.pipeline import DEPLOYED_CALIBRATION  # deferred: pulls in scipy; keeps the commands' --help light

    if not system.sets("monitor.spec"):
        return None if system.sets("monitor.calibration") else DEPLOYED_CALIBRATION
    return system.path_of("monitor.calibration")


def check_deployed_calibration(system: SystemFile) -> None:
    """Refuse a deployed monitor whose spec carries a threshold other than its card's (or is not the card's
    monitor): ``SystemFileError``, one line naming the file, the card, the spec and both thresholds (a card that
    cannot be read: its ``CalibrationError``)."""
    card = deployed_card(system)
    if card is None:
        return
    try:
        check_card_spec(load_calibration(card), monitor_spec(system))
    except CalibrationError as exc:
        raise system.error("monitor.spec", str(exc)) from None


def data_root(system: SystemFile, split: str, given: str | Path | None = None) -> Any:
    """The data set of a split: the option given (a folder, its layout detected), else ``[data] <split>``: a folder,
    or a table read as an ``assurance.dataio.layouts.DataSpec`` (its ``path`` resolved against the file's folder);
    a clear error when neither, or for a bad table or a missing folder. Path-like either way."""
    if given is not None:
        return Path(given)
    value = system.get(f"data.{split}")
    if value is None:
        raise system.error(f"data.{split}", f"not set; give the {split} data with --data or in [data] {split}")
    source: Any = system.path_of(f"data.{split}")
    if isinstance(value, Mapping):
        try:
            source = DataSpec.from_dict({**value, "path": system.path_of(f"data.{split}.path")})
        except ValueError as exc:
            raise system.error(f"data.{split}", str(exc)) from None
    if not Path(source).is_dir():
        raise system.error(f"data.{split}", f"{source}: no such folder")
    return source


def targets(system: SystemFile) -> dict[str, Any]:
    """The requirement parameters this system sets: ``[targets]``, R and beta of ``[safety]``, the deployed
    monitor and its calibration card of ``[monitor]`` (only those the file itself sets; none for the embedded
    default, whose values are the registry's own)."""
    if system.default:
        return {}
    out: dict[str, Any] = dict(system.document.get("targets") or {})
    for key in ("radius_m", "beta"):
        if system.sets(f"safety.{key}"):
            out[key] = system.get(f"safety.{key}")
    if system.sets("monitor.spec"):
        out["deployed_monitor"] = system.get("monitor.spec")
        out["calibration_card"] = None  # the shipped card calibrates the shipped monitor, not this one
    if system.sets("monitor.calibration"):
        out["calibration_card"] = str(system.path_of("monitor.calibration"))
    return out


TARGET_ORIGINS = {"radius_m": "[safety] radius_m", "beta": "[safety] beta", "deployed_monitor": "[monitor] spec",
                  "calibration_card": "[monitor] calibration"}
"""Where a system file sets each requirement parameter that is not under ``[targets]``."""


def target_origins(system: SystemFile) -> dict[str, str]:
    """Where in the file each parameter of :func:`targets` is set: its section and key (a calibration card unset
    because the file names a monitor of its own says so)."""
    out = {}
    for key in targets(system):
        if key == "calibration_card" and not system.sets("monitor.calibration"):
            out[key] = "[monitor] spec (a monitor of its own: the shipped card does not calibrate it)"
        else:
            out[key] = TARGET_ORIGINS.get(key, f"[targets] {key}")
    return out


def shipped_waivers() -> Path:
    """The waivers of the shipped system (``assurance/waivers.yaml``, package data: found by an installed wheel)."""
    from importlib import resources

    return Path(str(resources.files("assurance").joinpath("waivers.yaml")))


def waivers(system: SystemFile, given: str | None = None) -> str | None:
    """The waiver file: the option given, else ``[waivers] file``, else, for the embedded default system (the
    shipped one), the shipped waivers; a system file of the user's without ``[waivers]`` has none (the shipped
    waivers document the shipped system's deviations, not another system's)."""
    if given is not None:
        return given
    p = system.path_of("waivers.file")
    if p is not None:
        return str(p)
    return str(shipped_waivers()) if system.default else None


def report_settings(system: SystemFile) -> dict[str, Any]:
    """Title, organisation and template folder of the evidence report (``[report]``)."""
    templates = system.path_of("report.templates")
    return {"title": system.get("report.title"), "organisation": system.get("report.organisation"),
            "templates": None if templates is None else str(templates)}


def describe_path(p: Path | None) -> str:
    return "" if p is None else str(p)


def in_service(system: SystemFile) -> dict[str, Any]:
    """The safety performance indicators ``[in_service]`` declares (``uav-el in-service``, ``assurance.inservice``):
    empty when the file declares none."""
    return dict(system.get("in_service") or {})
