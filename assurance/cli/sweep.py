"""``uav-el sweep``: replay a campaign's decisions at every threshold of its monitors, and pick one."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from assurance.errors import CommandError, RunError
from assurance.files import atomic_write_bytes
from el.segmentation.factory import load_model

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


def run(args: argparse.Namespace) -> int:
    from assurance.analysis.criteria import (
        criterion_line,
        sweep_by_criterion,
    )  # deferred: pulls in pandas, scipy; keeps sweep --help light
    from assurance.analysis.sweep import SweepError  # deferred: pulls in pandas; keeps sweep --help light
    from assurance.analysis.sweep_report import write_sweep  # deferred: pandas, matplotlib; keeps sweep --help light
    from assurance.campaign.readouts import load_table  # deferred: pulls in pandas; keeps sweep --help light

    run_dir = Path(args.run)
    if not run_dir.is_dir():
        raise CommandError(f"{run_dir}: no such run folder")
    try:
        images, candidates = load_table(run_dir, "images"), load_table(run_dir, "candidates")
        table, choices = sweep_by_criterion(images, candidates, args.monitors, args.walks, args.criterion,
                                            recall=args.recall, miss_rate=args.miss_rate, confidence=args.confidence)
    except (SweepError, RunError, ValueError) as exc:
        raise CommandError(f"{run_dir}: {exc}") from None
    out = args.out or run_dir
    gate = None
    if args.gate:
        if not args.data:
            raise CommandError("--gate needs --data (the run's scenes)")
        gate = bound_gate(args.gate, run_dir)  # refused before anything is written
    md = write_sweep(out, table, choices, note=criterion_line(args.criterion, args.recall))
    if gate is not None:
        md += gate_section(run_dir, Path(args.data), gate, images, candidates, choices[0], out)
        atomic_write_bytes(out / "sweep.md", md.encode())
    if args.choose:
        print(md)
    else:
        print(f"{len(table)} rows for {len(choices)} monitor(s)")
    print(f"sweep written to {out / 'sweep.csv'}, {out / 'sweep.md'} and {out / 'sweep.png'}")
    return 0


def run_model(run_dir: Path) -> str | None:
    """The model spec a campaign run scored with, from its manifest (None: the shipped weights)."""
    from assurance.campaign import readouts  # deferred: pulls in pandas (readouts); keeps sweep --help light

    return readouts.read_manifest(run_dir).get("config", {}).get("weights")


def bound_gate(path: str, run_dir: Path) -> tuple[str, Any, Any]:
    """(path, gate, the run's model) for a gate fitted on the network the run segmented with; else exit 2."""
    from assurance.analysis.ood_replay import load_gate  # deferred: pulls in pandas, scipy; keeps sweep --help light

    try:
        gate = load_gate(path)
        model = load_model(run_model(run_dir))
        gate.check_network(model)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    return path, gate, model


def gate_section(run_dir: Path, data: Path, bound: tuple[str, Any, Any], images, candidates, best, out: Path) -> str:
    """Markdown: what the gate would change for the best choice (its distances cached per gate in
    ood_distances-<gate sha256>.csv)."""
    import pandas as pd

    from assurance.analysis.ood_replay import (
        frame_distances,
        gate_effect,
    )  # deferred: pulls in pandas, scipy; keeps sweep --help light
    from assurance.analysis.sweep import monitor_rows, replay  # deferred: pulls in pandas; keeps sweep --help light

    gate, loaded, model = bound
    cache = out / f"ood_distances-{loaded.sha256[:12]}.csv"
    if cache.is_file():
        dist = pd.read_csv(cache, dtype={"key": str})
    else:
        try:
            dist = frame_distances(run_dir, data, gate, model)
        except ValueError as exc:
            raise CommandError(str(exc)) from None
        atomic_write_bytes(cache, dist.to_csv(index=False).encode())
    im, ca = monitor_rows(images, candidates, best.monitor)
    eff = gate_effect(replay(im, ca, best.threshold, best.walk), dist)
    lines = ["", f"Frame gate `{gate}` on `{best.monitor}` ({best.walk} walk) at threshold "
                 f"{best.threshold:.6g}:", "",
             "| perturbation | frames | gate fires | unsafe landings without gate | with gate |",
             "|---|---|---|---|---|"]
    lines += [f"| {r.perturbation} | {r.frames} | {r.gate_fires} | {r.unsafe_without_gate} | {r.unsafe_with_gate} |"
              for r in eff.itertuples()]
    return "\n".join(lines) + "\n"
