"""``uav-el benchmark``: compare runtime monitors on validation scenes (docs/monitor-benchmark.md).

Reads a campaign run (``RUN``), or runs one (``--data``, preset ``benchmark``) into ``--out``/run, optionally
after fitting the feature-space detectors on training scenes (``--fit``). Writes ``benchmark.md``,
``benchmark.csv``, ``blocks.csv`` and the critical-difference diagram ``cd.png`` into ``--out``."""

from __future__ import annotations

import argparse
from pathlib import Path

WORK = "assurance.cli.benchmark_run"
"""Its work, imported only when it runs (heavy imports at its top: --help stays light)."""

CRITERIA = ("fewest-unsafe", "g-star", "guarantee", "f1", "g-mean", "tnr-at-recall")


HELP = ("compare monitors on validation scenes (never the test split): per perturbation AUROC, miss and false-alarm "
        "rates, unsafe landings and G* at each threshold criterion's threshold (fewest-unsafe, g-star, guarantee, f1, "
        "g-mean, tnr-at-recall); rank the monitors across perturbations or scenes with the Friedman test and draw the "
        "Nemenyi critical-difference diagram (cd.png). A monitor that beats the deployed one is reported, not deployed")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", nargs="?", help="a campaign run folder to read (else one is run on --data into OUT/run)")
    p.add_argument("--out", required=True, type=Path, help="folder for benchmark.md, benchmark.csv, blocks.csv, "
                                                          "cd.png (and run/, fitted detectors with --fit)")
    p.add_argument("--data", help="validation scenes to run the campaign on (default: the system file's [data] val)")
    p.add_argument("--fit", metavar="TRAIN", help="fit the mahalanobis, gmm and outside_box detectors on these "
                                                  "training scenes (every 5th held out for their default threshold) "
                                                  "and add them to the monitors")
    p.add_argument("--monitors", nargs="+", metavar="SPEC", help="monitors to compare (default: the benchmark "
                                                                 "preset's, or every scored one of RUN)")
    p.add_argument("--criteria", nargs="+", choices=CRITERIA, metavar="NAME",
                   default=["fewest-unsafe", "g-star", "f1", "g-mean", "tnr-at-recall"],
                   help="threshold criteria: " + ", ".join(CRITERIA) + " (default: all but guarantee, which needs "
                        "59 unsafe candidates for 0.05 at 0.95)")
    p.add_argument("--recall", type=float, default=0.95, help="the recall of tnr-at-recall (0.95)")
    p.add_argument("--miss-rate", type=float, default=0.05, help="the miss rate of guarantee (0.05)")
    p.add_argument("--confidence", type=float, default=0.95, help="the confidence of guarantee (0.95)")
    p.add_argument("--blocks", choices=("perturbation", "scene"), default="perturbation",
                   help="the Friedman test's blocks: the run's perturbations (default) or its scenes")
    p.add_argument("--rank-by", choices=("auroc", "g_star"), default="auroc",
                   help="the measure ranked (higher = better): AUROC (default) or G* at --rank-criterion's threshold")
    p.add_argument("--rank-criterion", choices=CRITERIA, default="fewest-unsafe",
                   help="the criterion whose threshold G* is ranked at (with --rank-by g_star)")
    p.add_argument("--alpha", type=float, default=0.05, help="significance level of the Nemenyi test (0.05)")
    p.add_argument("--images", type=int, help="use the first N scenes of --data and of --fit")
    p.add_argument("--perturbations", nargs="+", metavar="NAME", help="perturbations (default: the preset's six)")
    p.add_argument("--jobs", type=int, default=1, help="campaign workers (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress, nothing on standard output")
