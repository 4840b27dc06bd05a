"""``uav-el sweep``: replay a campaign's decisions at every threshold of its monitors, and pick one."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.cli import CommandError

HELP = ("replay a campaign at every threshold of its monitors (unsafe landings, G*, default share, miss and FP "
        "rates per perturbation) from the recorded scores; --choose picks the threshold with the fewest unsafe "
        "landings (run it on validation scenes, never on the test split)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="campaign run folder (its readouts must hold scores)")
    p.add_argument("--monitors", nargs="+", metavar="NAME",
                   help="configurations to sweep, as named in the run (default: every one with scores)")
    p.add_argument("--out", type=Path, help="folder for sweep.csv, sweep.md and sweep.png (default: the run folder)")
    p.add_argument("--choose", action="store_true", help="print the threshold each monitor would be deployed at, "
                                                          "and the best of them")


def run(args: argparse.Namespace) -> int:
    from assurance.readouts import RunError, load_table
    from assurance.sweep import SweepError
    from assurance.sweep_report import sweep_run, write_sweep

    run_dir = Path(args.run)
    if not run_dir.is_dir():
        raise CommandError(f"{run_dir}: no such run folder")
    try:
        images, candidates = load_table(run_dir, "images"), load_table(run_dir, "candidates")
        table, choices = sweep_run(images, candidates, args.monitors)
    except (SweepError, RunError) as exc:
        raise CommandError(f"{run_dir}: {exc}") from None
    out = args.out or run_dir
    md = write_sweep(out, table, choices)
    if args.choose:
        print(md)
    else:
        print(f"{len(table)} rows for {len(choices)} monitor(s)")
    print(f"sweep written to {out / 'sweep.csv'}, {out / 'sweep.md'} and {out / 'sweep.png'}")
    return 0
