"""``uav-el fit-ood``: fit the out-of-domain frame gate and write its hash-checked JSON file."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.cli.arguments import fit_split_options
from assurance.cli.fit_monitor import write_json
from assurance.errors import CommandError

HELP = ("fit the out-of-domain frame gate (Mahalanobis distance of pooled encoder features, Ledoit-Wolf) on a "
        "split, threshold at a quantile of --val distances; --report DIR adds the distances under each perturbation")


def add_arguments(p: argparse.ArgumentParser) -> None:
    fit_split_options(p)
    p.add_argument("--quantile", type=float, default=0.995, help="threshold quantile of validation distances")
    p.add_argument("--images", type=int, help="use the first N scenes of each split")
    p.add_argument("--report", type=Path, metavar="DIR",
                   help="write ood_shift.{csv,md,png}: --val distances as they are and under each perturbation")
    p.add_argument("--severity", type=int, default=3, help="perturbation severity of the report (3)")


def run(args: argparse.Namespace) -> int:
    from assurance.cli.system_options import load_model, model_spec, system_of, train_val_dirs
    from assurance.fitting.network_identity import network_record
    from assurance.fitting.ood_gate import fit_ood, ood_shift_report
    from el.monitors.ood import load_ood

    system = system_of(args)
    train_val_dirs(args, system)
    try:
        segmenter = load_model(args)
        doc = fit_ood(args.data, args.val, segmenter, quantile=args.quantile, images=args.images,
                      weights=network_record(segmenter, model_spec(args)), progress=not args.quiet)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    write_json(args.out, doc)
    b = doc["body"]
    print(f"out-of-domain gate ({b['embedding']}, {b['dims']} dims, shrinkage {b['shrinkage']:.3f}): threshold "
          f"{b['threshold']:.4g} = {b['quantile']:g} quantile of {b['validation']['frames']} validation frames")
    print(f"gate written to {args.out}")
    if args.report is not None:
        rows = ood_shift_report(load_ood(args.out), args.val, segmenter, out=args.report, severity=args.severity,
                                images=args.images)
        for r in rows:
            print(f"  {r['perturbation']:<12} median {r['median']:.4g}  p95 {r['p95']:.4g}  "
                  f"above threshold {r['above_threshold']:.1%}")
        print(f"report written to {args.report}/ood_shift.{{csv,md,png}}")
    return 0
