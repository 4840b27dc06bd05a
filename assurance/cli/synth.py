"""``uav-el synth``: write synthetic oblique urban scenes in the UAVid layout (images, labels, meta)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from assurance.errors import CommandError

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


def run(args: argparse.Namespace) -> int:
    from assurance.scenes import write_dataset
    from assurance.scenes.generate import scene_complete

    size = parse_size(args.size)
    if args.scenes < 1:
        raise CommandError(f"--scenes must be at least 1, got {args.scenes}")
    if args.seed < 0 or args.seed + args.scenes > 1_000_000:
        raise CommandError(f"--seed must be >= 0 and --seed + --scenes <= 1000000, got {args.seed} + {args.scenes}")
    if args.jobs < 1:
        raise CommandError(f"--jobs must be at least 1, got {args.jobs}")
    if args.out.exists() and not args.out.is_dir():
        raise CommandError(f"{args.out}: exists and is not a folder")
    done_before = sum(scene_complete(args.out, i) for i in range(args.scenes))
    write_dataset(args.out, args.scenes, args.seed, args.split, size, progress=not args.no_progress, jobs=args.jobs)
    written = args.scenes - done_before
    print(f"{args.out}: {written} scene(s) written, {done_before} already complete "
          f"({args.split}, seeds {args.seed}..{args.seed + args.scenes - 1}, {size[0]}x{size[1]})", file=sys.stdout)
    return 0
