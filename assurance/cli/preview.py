"""``uav-el preview``: image | colour labels side by side for one or more samples of a dataset."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.cli.system_options import system_of
from assurance.dataio.layouts import iter_samples, read_sample_labels
from assurance.dataio.uavid import read_image, write_image
from assurance.errors import CommandError
from assurance.scenes.preview import make_preview

HELP = "Write a preview PNG of a dataset (any layout): image | colour labels side by side, with a legend."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", type=Path, help="dataset folder, its layout detected (uavid, semantic-drone, "
                        "aeroscapes); default: the system file's [data] test (a folder or a table)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--index", type=int, help="preview sample K (0-based, in sorted order; default 0)")
    which.add_argument("--count", type=int, help="preview the first K samples, one row each")
    parser.add_argument("--out", required=True, type=Path, help="output PNG file")
    parser.add_argument("--width", type=int, default=800, help="width of each panel in pixels (default 800)")


def run(args: argparse.Namespace) -> int:
    labels = system_of(args).labels()  # the system's classes: its palette and its legend

    if args.out.suffix.lower() != ".png":
        raise CommandError(f"--out must be a .png file, got {args.out}")
    if not 64 <= args.width <= 4096:
        raise CommandError(f"--width must lie in [64, 4096], got {args.width}")
    args.data = system_of(args).data("test", args.data)  # --data, else [data] test
    samples = list(iter_samples(args.data, poses=True))  # the poses file checked as the campaign checks it
    if args.count is not None:
        if args.count < 1:
            raise CommandError(f"--count must be at least 1, got {args.count}")
        chosen = samples[: args.count]
    else:
        index = 0 if args.index is None else args.index
        if not 0 <= index < len(samples):
            raise CommandError(f"--index {index} is out of range: {args.data} has {len(samples)} sample(s)")
        chosen = [samples[index]]
    pairs = []
    for s in chosen:
        image, ids = read_image(s.image_path), read_sample_labels(s, labels)
        if image.shape[:2] != ids.shape:
            raise CommandError(f"{s.label_path}: label size differs from its image {s.image_path}")
        pairs.append((image, ids))
    write_image(args.out, make_preview(pairs, labels=labels, panel_width=args.width))
    print(f"{args.out}: preview of {len(pairs)} sample(s) from {args.data}")
    return 0
