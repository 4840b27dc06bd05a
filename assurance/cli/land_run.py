"""The work of ``uav-el land`` (its options: ``assurance.cli.land``)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from assurance.campaign.gt_pipeline import decide_from_label_file
from assurance.cli.system_options import assessed, system_of
from assurance.dataio.uavid import image_size, read_image, write_image
from assurance.errors import CommandError
from assurance.evidence.overlay import draw_decision
from assurance.files import atomic_write_bytes
from el.base.decision import Decision
from el.base.imageio import check_max_pixels
from el.flight.flightlog import FlightLog
from el.flight.kernel import FramePose, frame_core
from el.flight.pipeline import EmergencyLanding, FrameFile, PipelineConfig
from el.geometry.camera import Pose, geometry_problem
from el.geometry.config import CoreConfig, make_intrinsics
from el.monitors.calibration import load_calibration


def config_from_args(args: argparse.Namespace, base: CoreConfig, poses: str,
                     label: str) -> tuple[CoreConfig, Pose | None]:
    """The CM configuration and the frame's pose: the system's configuration ``base`` (camera, nominal pose, safety
    radius) with the lens, mode and working-width options given on the command line winning, and the pose
    ``--height``/``--pitch`` give (over the nominal pose's other value; None when neither is given: the nominal
    pose). ``poses`` is the system's pose policy, ``label`` names its file. CommandError names a bad value."""
    if poses == "required" and (args.height is None or args.pitch is None):
        raise CommandError(f"{label}: camera.poses is 'required' (every frame flies its own pose): give this "
                           "frame's --height and --pitch")
    lens = (args.camera, args.sensor_width, args.sensor_height, args.focal, args.hfov)
    try:
        intrinsics = base.intrinsics if all(v is None for v in lens) else make_intrinsics(
            args.camera, sensor_width_mm=args.sensor_width, sensor_height_mm=args.sensor_height, focal_mm=args.focal,
            hfov_deg=args.hfov)
        pose = None if args.height is None and args.pitch is None else Pose(
            height_m=base.pose.height_m if args.height is None else args.height,
            pitch_deg=base.pose.pitch_deg if args.pitch is None else args.pitch)
        core = replace(base, mode=args.mode or base.mode, working_width=args.working_width or base.working_width,
                       intrinsics=intrinsics)
        frame_core(core, pose)  # the pose checked with the rest
        return core, pose
    except ValueError as exc:
        raise CommandError(f"camera/pose options: {exc}") from None


def check_frame_geometry(config: CoreConfig, path: Path, roll_deg: float,
                         size: tuple[int, int] | None = None) -> None:
    """Refuse (one line) a camera, pose and roll the flat-ground model cannot plan with on this frame's size
    (``size``, else read from the file's header)."""
    width, height = size or image_size(path)
    problem = geometry_problem(config.geometry(width, height), roll_deg=roll_deg)
    if problem:
        raise CommandError(f"{path}: {problem}")


OVERLAY_SUFFIXES = (".png", ".jpg", ".jpeg")


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse output paths that cannot be written, before anything is computed or written."""
    for flag, path in (("--json", args.json), ("--overlay", args.overlay)):
        if path is None:
            continue
        if path.is_dir():
            raise CommandError(f"{flag} {path}: is a folder; give a file name")
        if path.parent.exists() and not path.parent.is_dir():
            raise CommandError(f"{flag} {path}: cannot write: {path.parent} is not a folder")
    if args.overlay is not None and args.overlay.suffix.lower() not in OVERLAY_SUFFIXES:
        raise CommandError(f"--overlay {args.overlay}: unknown image type {args.overlay.suffix or '(none)'!r}; "
                           f"give a {', '.join(OVERLAY_SUFFIXES)} file")
    if args.json is not None and args.overlay is not None and args.json.resolve() == args.overlay.resolve():
        raise CommandError(f"--json and --overlay name the same file {args.json}")


def run(args: argparse.Namespace) -> int:
    check_outputs(args)

    if args.labels is None:
        if args.image_arg is None:
            raise CommandError("give an IMAGE (model pipeline) or --labels LABELS.png (ground truth)")
        return run_model(args)
    image_path = args.image
    if args.image_arg is not None:
        if image_path is not None and Path(args.image_arg) != image_path:
            raise CommandError(f"two images given ({args.image_arg} and {image_path}): give one")
        image_path = Path(args.image_arg)

    system = system_of(args)
    config, pose = config_from_args(args, system.core(), system.poses(),
                                    system.label)
    if args.labels.is_file():  # a missing file is the reader's one-line error
        check_frame_geometry(frame_core(config, pose), args.labels, args.roll)
    encoding, offset = label_reading(system, args.label_encoding, args.id_offset)
    decision, ids = decide_from_label_file(args.labels, image_path=image_path, config=config,
                                           pose=FramePose(pose, "command_line", args.roll),
                                           labels=system.labels(), odd=system.odd(), encoding=encoding,
                                           id_offset=offset)
    image = read_image(image_path) if image_path is not None else None  # a bad image is an error too

    _write_outputs(args, decision, image=image, labels=ids)
    print(summary(decision))
    return 0


def label_reading(system: Any, encoding: str | None, id_offset: int | None) -> tuple[str, int]:
    """How a label file given alone is read: ``encoding`` and ``id_offset`` as given, else the system file's ``[data]``
    splits' (test, else val, else train: the first that declares a ``label_encoding``), else colours."""
    if encoding is None:
        for split in ("test", "val", "train"):
            spec = system.data(split) if system.declares_data(split) else None
            if getattr(spec, "label_encoding", None):
                encoding = spec.label_encoding
                id_offset = id_offset if id_offset is not None else (getattr(spec, "id_offset", 0) or 0)
                break
    return encoding or "rgb", int(id_offset or 0)


def run_model(args: argparse.Namespace) -> int:
    """The model pipeline (el.flight.pipeline): the system's network, monitor and frame gate built once, the frame
    decoded
    once, then segmentation -> frame gate -> candidates -> monitored walk."""
    if args.image is not None:
        raise CommandError("--image is for the ground-truth pipeline; give the image as IMAGE")
    check_max_pixels(args.max_pixels)
    frame = FrameFile.read(args.image_arg, max_pixels=args.max_pixels)  # a usage error here (in flight: default)
    system = assessed(args)  # the system under assessment, with --model and --gate
    core, pose = config_from_args(args, system.core, system.poses, system.label)
    check_frame_geometry(frame_core(core, pose), frame.path, args.roll, (frame.rgb.shape[1], frame.rgb.shape[0]))
    monitor, calibration = _monitor_of(args, system)
    segmenter = _network(args, system, core)
    config = system.flight_config(core=core, monitor=monitor, seed=args.seed, evaluate_all=args.evaluate_all,
                                  time_budget_s=args.budget if args.budget is not None else system.budget_s,
                                  max_pixels=args.max_pixels, calibration=str(calibration) if calibration else None)
    log = _flight_log(args, system)
    landing = EmergencyLanding(config, segmenter=segmenter, log=log)  # the monitor built and the gate bound, once
    for part in ("monitor", "frame_gate"):  # a part that cannot fly is a usage error here (in flight: default action)
        if part in landing.errors:
            raise landing.errors[part]
    decision = landing.decide(frame, pose=pose, pose_source="command_line")
    _write_outputs(args, decision, image=frame.rgb if args.overlay else None, labels=None)
    print(summary(decision))
    if log is not None:
        log.close()
        if log.failures:
            print(f"warning: {args.log}: the decision's record could not be written ({log.last_error})",
                  file=sys.stderr)
    return 3 if decision.reason.startswith("fault") else 0


def _flight_log(args: argparse.Namespace, system: Any) -> Any:
    """The flight log ``--log`` names (appended to), the system file's SHA-256 its identity; None without it."""
    if args.log is None:
        return None

    if not args.log.parent.is_dir():  # said here in one line; the flight function would log it as well
        raise CommandError(f"{args.log}: cannot open the flight log: no folder {args.log.parent}")
    log = FlightLog(args.log, system_sha256=system.file.sha256)
    if log.fault:
        raise CommandError(log.fault)
    return log


def _monitor_of(args: argparse.Namespace, system: Any) -> tuple[str | None, Path | None]:
    """The monitor spec and calibration card to fly: ``--monitor``/``--calibration``, else the system's deployed
    pair (a card given without a spec deploys the card's own monitor)."""
    if args.monitor is None and args.calibration is None:
        return system.deployed()

    monitor, calibration = args.monitor or system.monitor or PipelineConfig().monitor, \
        args.calibration or system.calibration
    if calibration is not None and not args.monitor:
        own = args.calibration is None and system.file.names_monitor  # the system's pair: its spec on its card
        if not own:
            monitor = load_calibration(calibration).monitor  # a bad card: its one line, exit 2
    return monitor, calibration


def _network(args: argparse.Namespace, system: Any, core: CoreConfig) -> Any:
    """The system's network, loaded once; a model named here that cannot be loaded is a usage error (one line, exit
    2), the shipped one missing a flight fault (None: the default action, exit 3)."""
    try:
        return system.segmenter(threads=args.threads, working_width=core.working_width)
    except ValueError as exc:  # WeightsError
        if not system.shipped_network:
            raise CommandError(str(exc)) from None
        return None


def _write_outputs(args: argparse.Namespace, decision: Decision, *, image, labels) -> None:
    try:
        if args.json is not None:
            atomic_write_bytes(args.json, (decision.to_json() + "\n").encode("utf-8"))
            print(f"decision written to {args.json}")
        if args.overlay is not None:

            palette = system_of(args).labels()  # the label map's own palette
            write_image(args.overlay, draw_decision(decision, image=image, labels=labels, label_set=palette))
            print(f"overlay written to {args.overlay}")
    except OSError as exc:
        where = exc.filename or args.json or args.overlay
        raise CommandError(f"{where}: cannot write: {exc.strerror or exc}") from None


def summary(decision: Decision) -> str:
    """A few human-readable lines: the decision, the best candidates, the time spent."""
    info = decision.input
    exif = f", EXIF orientation {info['exif_orientation']} applied" if info.get("exif_orientation") else ""
    lines = [f"{info.get('path', '<array>')} ({info.get('width')}x{info.get('height')}{exif}): "
             f"{len(decision.candidates)} candidate(s)"]
    if decision.selected is not None:
        c = decision.candidates[decision.selected]
        lines.append(
            f"decision: LAND on candidate #{c.rank} at x={c.x:.1f} y={c.y:.1f} r={c.radius_px:.1f} px, "
            f"hazard {c.hazard:.3f} (semantic {c.hazard_semantic:.3f}, distance {c.hazard_distance:.3f}); "
            f"reason: {decision.reason}" + ("" if c.monitor else " (no monitor)")
        )
    else:
        a = decision.default_area
        lines.append(
            f"decision: DEFAULT action (parachute) at x={a.x:.1f} y={a.y:.1f} r={a.radius_px:.1f} px; "
            f"reason: {decision.reason}"
        )
    for c in decision.candidates[1:5]:
        lines.append(f"  #{c.rank}: x={c.x:.1f} y={c.y:.1f} r={c.radius_px:.1f} hazard {c.hazard:.3f}")
    if len(decision.candidates) > 5:
        lines.append(f"  ... {len(decision.candidates) - 5} more")
    gate = info.get("frame_gate")
    if gate:
        score = "not scored" if gate.get("score") is None else f"score {gate['score']:.4g}"
        lines.append(f"frame gate ({gate['kind']}): {score}, threshold {gate['threshold']:.4g}")
    total = decision.timings.get("total_s")
    if total is not None:
        cand_ms = 1000 * (decision.timings.get("candidates_s") or 0.0)
        lines.append(f"time: {1000 * total:.0f} ms (candidates {cand_ms:.0f} ms)")
    return "\n".join(lines)
