"""The work of ``uav-el sweep`` (its options: ``assurance.cli.sweep``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from assurance.analysis.criteria import criterion_line, sweep_by_criterion
from assurance.analysis.ood_replay import frame_distances, gate_effect, load_gate
from assurance.analysis.sweep import SweepError, monitor_rows, replay
from assurance.analysis.sweep_report import write_sweep
from assurance.campaign import readouts
from assurance.campaign.readouts import load_table
from assurance.errors import CommandError, RunError
from assurance.files import atomic_write_bytes
from el.segmentation.factory import load_model


def run(args: argparse.Namespace) -> int:
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

    return readouts.read_manifest(run_dir).get("config", {}).get("weights")


def bound_gate(path: str, run_dir: Path) -> tuple[str, Any, Any]:
    """(path, gate, the run's model) for a gate fitted on the network the run segmented with; else exit 2."""

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
