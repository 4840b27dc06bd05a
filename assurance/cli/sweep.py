"""``uav-el sweep``: replay a campaign's decisions at every threshold of its monitors, and pick one."""

from __future__ import annotations

import argparse
from pathlib import Path

WORK = "assurance.cli.sweep_run"
"""Its work, imported only when it runs (heavy imports at its top: --help stays light)."""

HELP = ("replay a campaign at every threshold of its monitors (unsafe landings, G*, default share, miss and FP "
        "rates per perturbation) from the recorded scores; --choose picks the threshold with the fewest unsafe "
        "landings (run it on validation scenes, never on the test split)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="campaign run folder (its readouts must hold scores)")
    p.add_argument("--monitors", nargs="+", metavar="NAME",
                   help="configurations to sweep, as named in the run (default: every one with scores)")
    p.add_argument("--walks", nargs="+", choices=("hazard", "score"),
                   help="walk orders to replay (el.monitors.walk; default: each configuration's own)")
    p.add_argument("--out", type=Path, help="folder for sweep.csv, sweep.md and sweep.png (default: the run folder)")
    p.add_argument("--gate", metavar="GATE.json", help="also replay a frame gate (uav-el fit-gate): the run's frames "
                                                        "are re-perturbed with its seeds and scored; needs --data")
    p.add_argument("--data", help="the run's scenes (for --gate)")
    p.add_argument("--criterion", default="fewest-unsafe", metavar="NAME",
                   choices=("fewest-unsafe", "g-star", "guarantee", "f1", "g-mean", "tnr-at-recall"),
                   help="how each monitor's threshold is chosen (written in sweep.md): fewest-unsafe (default, the "
                        "paper's), g-star, guarantee (calibration bound: --miss-rate, --confidence), f1, g-mean, "
                        "tnr-at-recall (--recall)")
    p.add_argument("--recall", type=float, default=0.95, help="recall of --criterion tnr-at-recall (0.95)")
    p.add_argument("--miss-rate", type=float, default=0.05, help="miss rate of --criterion guarantee (0.05)")
    p.add_argument("--confidence", type=float, default=0.95, help="confidence of --criterion guarantee (0.95)")
    p.add_argument("--choose", action="store_true", help="print the threshold each monitor would be deployed at, "
                                                          "and the best of them")
