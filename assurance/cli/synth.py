"""``uav-el synth``: write synthetic oblique urban scenes in the UAVid layout (images, labels, meta)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from assurance.errors import CommandError
from assurance.scenes import write_dataset
from assurance.scenes.generate import ViewPlan, scene_complete
from assurance.workers import bounded_jobs
from el.geometry.camera import CAMERAS, Pose
from el.geometry.config import make_intrinsics

HELP = "Generate synthetic oblique urban scenes (UAVid layout: Images, Labels, meta) with a progress bar."

_SIZE = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


def parse_size(text: str) -> tuple[int, int]:
    """'3840x2160' -> (3840, 2160); CommandError for anything else."""
    m = _SIZE.match(text)
    if not m:
        raise CommandError(f"--size must look like WIDTHxHEIGHT (e.g. 3840x2160), got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if w < 64 or h < 36 or w > 16384 or h > 16384:
        raise CommandError(f"--size must lie between 64x36 and 16384x16384, got {w}x{h}")
    return w, h


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, type=Path, help="dataset root (seqNN folders are created)")
    parser.add_argument("--scenes", required=True, type=int, help="number of scenes to write")
    parser.add_argument("--seed", type=int, default=0, help="offset of the first scene within the split (default 0)")
    parser.add_argument("--size", default="3840x2160", help="image size WIDTHxHEIGHT (default 3840x2160)")
    parser.add_argument("--split", choices=("train", "val", "test"), default="train",
                        help="split: disjoint seed ranges; val/test also draw held-out styles (default train)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    cam = parser.add_argument_group("camera and poses (default: phantom4 at 50 m, 45 degrees, no poses.csv)")
    cam.add_argument("--camera", choices=sorted(CAMERAS), default=None, help="camera preset")
    cam.add_argument("--sensor-width", type=float, metavar="MM", help="sensor width in millimetres")
    cam.add_argument("--sensor-height", type=float, metavar="MM", help="sensor height in millimetres (optional)")
    lens = cam.add_mutually_exclusive_group()
    lens.add_argument("--focal", type=float, metavar="MM", help="focal length in millimetres")
    lens.add_argument("--hfov", type=float, metavar="DEG", help="horizontal field of view in degrees")
    cam.add_argument("--height", type=float, metavar="M", help="nominal flight height in metres (default 50)")
    cam.add_argument("--pitch", type=float, metavar="DEG", help="nominal pitch below the horizon (default 45)")
    cam.add_argument("--heights", metavar="LOW:HIGH", help="per-scene heights drawn from this range (seeded)")
    cam.add_argument("--pitches", metavar="LOW:HIGH", help="per-scene pitches drawn from this range (seeded)")


def parse_range(flag: str, text: str | None) -> tuple[float, float] | None:
    """'20:120' -> (20.0, 120.0); None for None; CommandError naming the option otherwise."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        lo, hi = (float(p) for p in parts) if len(parts) == 2 else (float("nan"),) * 2
    except ValueError:
        lo = hi = float("nan")
    if not (lo <= hi):
        raise CommandError(f"{flag} must look like LOW:HIGH with LOW <= HIGH (e.g. 20:120), got {text!r}")
    return lo, hi


def view_from_args(args: argparse.Namespace, size: tuple[int, int]) -> ViewPlan:
    """The camera and poses of the options; CommandError (one line) for a value outside what is allowed."""
    try:
        intrinsics = make_intrinsics(args.camera, sensor_width_mm=args.sensor_width,
                                     sensor_height_mm=args.sensor_height, focal_mm=args.focal, hfov_deg=args.hfov)
        pose = Pose(height_m=Pose().height_m if args.height is None else args.height,
                    pitch_deg=Pose().pitch_deg if args.pitch is None else args.pitch)
        view = ViewPlan(intrinsics=intrinsics, pose=pose, heights=parse_range("--heights", args.heights),
                        pitches=parse_range("--pitches", args.pitches))
        if not view.is_default:
            view.check(size)
    except ValueError as exc:
        raise CommandError(f"camera/pose options: {exc}") from None
    return view


def run(args: argparse.Namespace) -> int:
    size = parse_size(args.size)
    view = view_from_args(args, size)
    if args.scenes < 1:
        raise CommandError(f"--scenes must be at least 1, got {args.scenes}")
    if args.seed < 0 or args.seed + args.scenes > 1_000_000:
        raise CommandError(f"--seed must be >= 0 and --seed + --scenes <= 1000000, got {args.seed} + {args.scenes}")
    if args.jobs < 1:
        raise CommandError(f"--jobs must be at least 1, got {args.jobs}")

    args.jobs = bounded_jobs(args.jobs, warn=lambda m: print(f"uav-el synth: warning: {m}", file=sys.stderr))
    if args.out.exists() and not args.out.is_dir():
        raise CommandError(f"{args.out}: exists and is not a folder")
    done_before = sum(scene_complete(args.out, i) for i in range(args.scenes))
    write_dataset(args.out, args.scenes, args.seed, args.split, size, progress=not args.no_progress, jobs=args.jobs,
                  view=view)
    written = args.scenes - done_before
    print(f"{args.out}: {written} scene(s) written, {done_before} already complete "
          f"({args.split}, seeds {args.seed}..{args.seed + args.scenes - 1}, {size[0]}x{size[1]})", file=sys.stdout)
    return 0
