"""``uav-el fit-monitor``: train the learned candidate monitor and write its hash-checked JSON model.

The system's network and label set decide everything: the label maps are read in the system's palette (the
classes a class-mapped network is seen in), the candidates' truth and per-class features use its forbidden
classes, and ``--mcd`` is refused, before any scene is read, for a network that offers no MC dropout."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from assurance.cli.arguments import model_option
from assurance.cli.system_options import assessed
from assurance.errors import CommandError
from assurance.files import atomic_write_bytes
from assurance.fitting.network_identity import network_record
from el.segmentation.contract import MC_DROPOUT, has_capability

HELP = ("train the learned candidate monitor (logistic regression on candidate features) on a split, select it "
        "on --val, and write its JSON model (no pickle, SHA-256 checked at load)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", help="training scenes with labels (e.g. data/train); default: the system file's "
                                  "[data] train")
    p.add_argument("--val", help="held-out scenes for C and the threshold (default: the system file's [data] val; "
                                 "without one, every 5th scene of --data)")
    p.add_argument("--out", required=True, type=Path, help="model file to write (e.g. el/monitors/data/learned.json)")
    model_option(p)
    p.add_argument("--recall", type=float, default=0.95,
                   help="threshold: the largest with this recall of unsafe held-out candidates (0.95)")
    p.add_argument("--mcd", type=int, default=0, metavar="N",
                   help="add MC-dropout spread features from N samples (0: off, the cheap default)")
    p.add_argument("--images", type=int, help="use the first N scenes of each split")
    p.add_argument("--working-width", type=int, help="working resolution width (default: the system's, [model] "
                                                      "working_width of the system file, else the flight code's)")


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from assurance.fitting.learned_monitor import (
        FeatureSettings,
        Selection,
        fit_learned_monitor,
    )  # deferred: pulls in scipy; keeps fit-monitor --help light

    system = assessed(args)
    args.data = system.data("train", args.data)
    if args.val is None and system.file.declares_data("val"):
        args.val = system.data("val")
    for d in (args.data, args.val):
        if d is not None and not Path(d).is_dir():
            raise CommandError(f"{d}: no such folder")
    try:
        selection = Selection(recall=args.recall)  # checked before the network loads
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    if args.mcd < 0:
        raise CommandError(f"--mcd must be >= 0, got {args.mcd}")
    core = system.core if args.working_width is None else replace(system.core, working_width=args.working_width)
    try:
        segmenter = system.segmenter(working_width=core.working_width)
        _check_mcd(args.mcd, segmenter, system.label)
        doc = fit_learned_monitor(args.data, segmenter, val=args.val,
                                  features=FeatureSettings(core=core, mcd_n=args.mcd),
                                  selection=selection, images=args.images,
                                  weights=network_record(segmenter, system.model), progress=not args.quiet)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    write_json(args.out, doc)
    b = doc["body"]
    s = b["selection"]
    print(f"learned monitor: C={b['C']:g}, held-out AUROC {s['held_out_auroc']:.3f}; threshold {b['threshold']:.4g} "
          f"(recall {s['held_out_recall']:.3f}, safe rejected {s['held_out_safe_rejected']:.3f}); trained on "
          f"{b['training']['candidates']} candidates ({b['training']['unsafe']} unsafe)")
    print(f"model written to {args.out} (sha256 {doc['sha256'][:12]}...)")
    return 0


def _check_mcd(n: int, segmenter: object, where: str) -> None:
    """Refuse ``--mcd N`` (N > 0) on a network without MC dropout: one line naming the system file."""
    if n > 0 and not has_capability(segmenter, MC_DROPOUT):
        raise CommandError(f"--mcd {n}: the network of {where} offers no MC dropout samples (an ONNX file has none); "
                           "fit the monitor without MC-dropout features (--mcd 0)")


def write_json(path: Path, doc: dict, *, indent: int = 1) -> None:
    """Write a JSON document atomically; an unwritable path is one line, exit 2."""
    try:
        atomic_write_bytes(path, (json.dumps(doc, indent=indent, sort_keys=True) + "\n").encode())
    except OSError as exc:
        raise CommandError(f"{path}: cannot write: {exc.strerror or exc}") from None
