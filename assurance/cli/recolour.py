"""``uav-el recolour``: rewrite a UAVid-layout data set's label maps into another label set's palette."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from assurance.errors import CommandError
from assurance.scenes.recolour import recolour_dataset
from el.classes.labels import load_label_set

HELP = ("copy a UAVid-layout data set with its label maps re-coloured into another label set's palette "
        "(images, meta and poses copied unchanged); classes are matched by a name map")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, type=Path, help="source data set (UAVid layout)")
    p.add_argument("--out", required=True, type=Path, help="new data set folder (must not exist or be empty)")
    p.add_argument("--to", required=True, metavar="LABELS",
                   help="target label set: a preset name (uavid, semantic_drone) or a YAML/JSON label file")
    p.add_argument("--from", dest="source", default="uavid", metavar="LABELS",
                   help="the source data's label set (default: uavid)")
    p.add_argument("--map", metavar="JSON", help="source class -> target class names as a JSON object (default: "
                                                 "the same names)")
    p.add_argument("--allow-unsafe", action="store_true",
                   help="allow mapping a forbidden class onto a safe one (refused by default)")


def run(args: argparse.Namespace) -> int:
    if not args.data.is_dir():
        raise CommandError(f"--data {args.data}: no such folder")
    mapping = None
    if args.map:
        try:
            mapping = json.loads(args.map)
        except json.JSONDecodeError as exc:
            raise CommandError(f"--map: not a JSON object: {exc}") from None
        if not isinstance(mapping, dict):
            raise CommandError("--map: give a JSON object of source class -> target class names")
    source, target = load_label_set(args.source), load_label_set(args.to)
    done = recolour_dataset(args.data, args.out, source, target, mapping, allow_unsafe=args.allow_unsafe)
    print(f"{args.out}: {done['labels']} label map(s) re-coloured from {source.name} to {target.name}")
    return 0
