"""``uav-el fit-gate``: fit the frame gate (``el.monitors.frame_gate``) and write its hash-checked JSON file."""

from __future__ import annotations

import argparse
import math
import sys

from assurance.cli.arguments import fit_split_options
from assurance.cli.fit_monitor import write_json
from assurance.cli.system_options import assessed, train_val_dirs
from assurance.errors import CommandError
from assurance.fitting.network_identity import network_record
from el.monitors.gates import GATES

HELP = ("fit the frame gate (a candidate of el.monitors.gates reading the frame pass's own features) on training "
        "scenes with the in-domain perturbations applied (the system file's [odd] perturbations, else the shipped "
        "six); threshold at a quantile of validation scenes at severity 3")
FEATURE_CHOICES = ("auto", "trunk", "output")  # assurance.fitting.frame_gate_fit.CHOICES (not imported at start-up)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--kind", choices=sorted(GATES), default="mahalanobis", help="gate (default: %(default)s)")
    p.add_argument("--features", choices=FEATURE_CHOICES, default="auto",
                   help="what a mahalanobis or knn gate reads: the trunk's pooled statistics (trunk), the pooled "
                        "statistics of the network's output, which every network has (output), or auto: the trunk's "
                        "where the network gives them, else the output's (default: %(default)s)")
    fit_split_options(p)
    p.add_argument("--quantile", type=float,
                   help="threshold: this quantile of the validation frames' scores (default: 0.997, the shipped "
                        "gate's, assurance.fitting.frame_gate_fit.DEFAULT_QUANTILE)")
    p.add_argument("--train-scenes", metavar="FIRST:END", help="training scenes to use (0-based, END excluded; "
                                                                "default: all)")
    p.add_argument("--val-scenes", metavar="FIRST:END",
                   help="validation scenes for the threshold (default: all); keep the others to measure the gate")
    p.add_argument("--working-width", type=int, default=None, metavar="PX",
                   help="working resolution width (default: the system file's, else the shipped one)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from assurance.campaign.perturbation_plan import fit_levels  # deferred: pandas, scipy; keeps fit-gate --help light
    from assurance.fitting.frame_gate_fit import (
        DEFAULT_QUANTILE,
        GateSettings,
        fit_gate,
        parse_scenes,
    )  # deferred: pulls in scipy; keeps fit-gate --help light

    system = assessed(args)
    levels = fit_levels(system)  # a system file's own [odd] perturbations; None: the shipped gate's six
    train_val_dirs(args, system.file)
    for flag, text in (("--train-scenes", args.train_scenes), ("--val-scenes", args.val_scenes)):
        try:
            parse_scenes(text)
        except ValueError as exc:
            raise CommandError(f"{flag}: {exc}") from None
    width = args.working_width or system.core.working_width
    try:
        segmenter = system.segmenter(working_width=width)
        quantile = DEFAULT_QUANTILE if args.quantile is None else args.quantile
        settings = GateSettings(kind=args.kind, quantile=quantile, features=args.features, perturbations=levels)
        doc = fit_gate(args.data, args.val, segmenter, settings=settings, train_scenes=args.train_scenes,
                       val_scenes=args.val_scenes, weights=network_record(segmenter, system.model),
                       progress=not (args.no_progress or getattr(args, "quiet", False)))
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    write_json(args.out, doc, indent=None)
    b = doc["body"]
    print(f"frame gate ({b['kind']} on the {_shown(b['features']['tap'])}, {b['features']['dims']} features): "
          f"threshold {b['threshold']:.4g} = {b['quantile']:g} quantile of {b['validation']['frames']} validation "
          f"frames; fitted on {b['training']['frames']} training frames")
    print(f"gate written to {args.out}")
    few = too_few_frames(b["quantile"], int(b["validation"]["frames"]))
    if few:
        print(f"warning: {few}", file=sys.stderr)
    return 0


def too_few_frames(quantile: float, frames: int) -> str | None:
    """Why ``frames`` validation frames cannot place a ``quantile`` threshold (fewer than 1 / (1 - quantile): the
    quantile is then their maximum, or beyond it, and the gate refuses in-domain frames at a rate no sample showed),
    None when they can."""
    needed = math.ceil(round(1 / (1 - quantile), 9)) if quantile < 1 else None  # 1 / (1 - 0.9) is 10.000...02
    if needed is None or frames >= needed:
        return None
    return (f"the {quantile:g} quantile of {frames} validation frames is their maximum, not a measured rate: at least "
            f"{needed} frames place it; expect the gate to refuse in-domain frames more often than "
            f"{1 - quantile:.1%} (more validation scenes, or a lower --quantile)")


def _shown(tap: str) -> str:
    """How the output names the statistics a gate reads."""
    return {"pooled": "trunk's statistics", "output": "output's statistics"}.get(tap, tap)
