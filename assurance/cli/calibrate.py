"""``uav-el calibrate``: choose a monitor's threshold on held-out scenes with a stated miss-rate guarantee."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.cli.arguments import model_option
from assurance.cli.fit_monitor import write_json
from assurance.cli.system_options import assessed
from assurance.errors import CommandError

HELP = ("calibrate a monitor's threshold on held-out scenes: P(accept an unsafe candidate) <= --miss-rate "
        "with --confidence (order statistic + Clopper-Pearson)")


DEFAULT_CONFIDENCE = 0.95
"""The card's confidence when neither ``--confidence`` nor the system file's ``[targets] confidence`` sets one."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", help="labelled calibration scenes, a folder of a known layout (uavid, semantic-drone, "
                                  "aeroscapes: detected; e.g. data/val); default: the system file's [data] val (a "
                                  "folder or a table); clean, and under each perturbation the system file "
                                  "declares in its own [odd] perturbations")
    p.add_argument("--monitor", metavar="SPEC", help="monitor to calibrate, e.g. lhd, msp (default: the system "
                                                    "file's [monitor] spec)")
    p.add_argument("--miss-rate", type=float, default=0.05, help="largest P(accept an unsafe candidate) (0.05)")
    p.add_argument("--confidence", type=float, help="confidence of the bound (default: the system file's [targets] "
                                                    f"confidence, else {DEFAULT_CONFIDENCE})")
    p.add_argument("--criterion", default="guarantee", choices=("guarantee", "f1", "g-mean", "tnr-at-recall"),
                   help="how the threshold is chosen (recorded in the card): guarantee (default: the miss-rate bound "
                        "above), or the monitor benchmark's f1, g-mean, tnr-at-recall (largest threshold with recall "
                        "of unsafe candidates >= --recall); those give no guarantee")
    p.add_argument("--recall", type=float, default=0.95, help="the recall of --criterion tnr-at-recall (0.95)")
    p.add_argument("--out", required=True, type=Path, help="calibration card to write (JSON)")
    model_option(p)
    p.add_argument("--images", type=int, help="use the first N scenes of --data")


def run(args: argparse.Namespace) -> int:
    from assurance.campaign.perturbation_plan import fit_levels  # deferred: pandas, scipy; keeps calibrate --help light
    from assurance.fitting.calibration import (
        CalibrationScenes,
        ThresholdRule,
        calibrate_on_data,
    )  # deferred: pandas, scipy; keeps calibrate --help light

    system = assessed(args)
    data = system.data("val", args.data)
    if not Path(data).is_dir():
        raise CommandError(f"{data}: no such folder")
    monitor = args.monitor or (system.monitor if system.file.names_monitor else None)
    if monitor is None:
        raise CommandError("give the monitor to calibrate with --monitor SPEC (or [monitor] spec in the system file)")
    try:
        confidence = args.confidence if args.confidence is not None else \
            float(system.file.targets().get("confidence", DEFAULT_CONFIDENCE))
        rule = ThresholdRule(miss_rate=args.miss_rate, confidence=confidence, criterion=args.criterion,
                             recall=args.recall)
        scenes = CalibrationScenes(images=args.images, core=system.core,
                                   perturbations=fit_levels(system))  # its own [odd] perturbations; None: clean
        doc = calibrate_on_data(data, monitor, rule=rule, scenes=scenes, weights=system.model,
                                progress=not args.quiet)
    except ValueError as exc:  # CalibrationError, WeightsError, a bad spec: one line
        raise CommandError(str(exc)) from None
    write_json(args.out, doc, indent=2)
    b = doc["body"]
    c = b["counts"]
    print(f"{b['spec']}: threshold {b['threshold']:.6g} from {c['unsafe']} truly unsafe of {c['candidates']} "
          f"candidates ({b['split']['images']} scenes); {c['unsafe_accepted']} unsafe accepted, "
          f"{c['safe_rejected']} of {c['safe']} safe rejected")
    print(f"criterion: {b['criterion']['name']}; guarantee: {b['guarantee']}")
    print(f"card written to {args.out}")
    return 0
