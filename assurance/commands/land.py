"""``uav-el land``: decide where to land for one frame, and say why.

Two pipelines (DESIGN section 5):
- ground truth: ``uav-el land --labels LABELS.png [--image IMAGE.png]`` runs the CM on the label
  map (a perfect segmentation), without a monitor; the image is only for drawing;
- model: ``uav-el land IMAGE.png [--monitor SPEC]`` segments the image first (not available yet).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.cli import CommandError
from el.camera import CAMERAS, Pose
from el.config import MODES, CoreConfig, camera_intrinsics
from el.decision import Decision
from el.uavid import atomic_write_bytes, read_image, write_image

HELP = "Decide where to land for one frame (ground-truth labels now; the model pipeline later)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("image_arg", nargs="?", metavar="IMAGE",
                        help="input image (the model pipeline; with --labels, the image to draw on)")
    parser.add_argument("--labels", type=Path, metavar="LABELS.png",
                        help="UAVid colour label map: run the ground-truth pipeline on it")
    parser.add_argument("--image", type=Path, metavar="IMAGE.png", help="image to draw the overlay on")
    parser.add_argument("--json", type=Path, metavar="OUT.json", help="write the decision as JSON")
    parser.add_argument("--overlay", type=Path, metavar="OUT.png", help="draw the decision into a PNG")
    parser.add_argument("--height", type=float, default=Pose().height_m, metavar="M",
                        help="flight height above the ground in metres (default: %(default)s)")
    parser.add_argument("--pitch", type=float, default=Pose().pitch_deg, metavar="DEG",
                        help="camera pitch below the horizon in degrees (default: %(default)s)")
    parser.add_argument("--camera", choices=sorted(CAMERAS), default="phantom4",
                        help="camera intrinsics (default: %(default)s)")
    parser.add_argument(
        "--mode", choices=MODES, default="exact",
        help="valid pixels: exact disc, or the paper's stripes and squares (default: %(default)s)",
    )
    parser.add_argument("--working-width", type=int, default=CoreConfig().working_width, metavar="PX",
                        help="working resolution width (default: %(default)s)")
    # The lead adds the model pipeline here: --monitor SPEC (runtime monitor), --weights, ...


def config_from_args(args: argparse.Namespace) -> CoreConfig:
    """The CM configuration of the command-line options (ValueError names a bad value)."""
    return CoreConfig(
        mode=args.mode,
        working_width=args.working_width,
        pose=Pose(height_m=args.height, pitch_deg=args.pitch),
        intrinsics=camera_intrinsics(args.camera),
    )


def run(args: argparse.Namespace) -> int:
    from el.gt_pipeline import decide_from_label_file

    if args.labels is None:
        if args.image_arg is None:
            raise CommandError("give an IMAGE (model pipeline) or --labels LABELS.png (ground truth)")
        # --- model pipeline: the lead plugs `decide(image, model, monitor, ...)` in here. ---
        raise CommandError("model pipeline not available yet (use --labels LABELS.png)")
    image_path = args.image
    if args.image_arg is not None:
        if image_path is not None and Path(args.image_arg) != image_path:
            raise CommandError(f"two images given ({args.image_arg} and {image_path}): give one")
        image_path = Path(args.image_arg)

    config = config_from_args(args)
    decision, ids = decide_from_label_file(args.labels, image_path=image_path, config=config)
    image = read_image(image_path) if image_path is not None else None  # a bad image is an error too

    try:
        if args.json is not None:
            atomic_write_bytes(args.json, (decision.to_json() + "\n").encode("utf-8"))
        if args.overlay is not None:
            from assurance.overlay import draw_decision

            write_image(args.overlay, draw_decision(decision, image=image, labels=ids))
    except OSError as exc:
        where = exc.filename or args.json or args.overlay
        raise CommandError(f"{where}: cannot write: {exc.strerror or exc}") from None
    print(summary(decision))
    if args.json is not None:
        print(f"decision written to {args.json}")
    if args.overlay is not None:
        print(f"overlay written to {args.overlay}")
    return 0


def summary(decision: Decision) -> str:
    """A few human-readable lines: the decision, the best candidates, the time spent."""
    info = decision.input
    lines = [f"{info.get('path', '<array>')} ({info.get('width')}x{info.get('height')}): "
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
    total = decision.timings.get("total_s")
    if total is not None:
        cand_ms = 1000 * (decision.timings.get("candidates_s") or 0.0)
        lines.append(f"time: {1000 * total:.0f} ms (candidates {cand_ms:.0f} ms)")
    return "\n".join(lines)
