"""The work of ``uav-el benchmark`` (its options: ``assurance.cli.benchmark``)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from assurance.analysis.benchmark import benchmark_table, block_measure, write_benchmark
from assurance.analysis.sweep import SweepError
from assurance.analysis.sweep_report import scored_monitors
from assurance.campaign.presets import preset_config
from assurance.campaign.readouts import load_table
from assurance.cli import campaign
from assurance.cli.fit_monitor import write_json
from assurance.cli.system_options import assessed
from assurance.dataio.layouts import iter_samples
from assurance.errors import CommandError, RunError
from assurance.fitting.detectors import FAMILIES, detector_document, fit_detector_body
from assurance.fitting.learned_monitor import FeatureSettings, collect_candidates
from assurance.fitting.network_identity import network_record
from el.monitors import monitor_name
from el.monitors.calibration import load_calibration
from el.segmentation.contract import labels_of


def run(args: argparse.Namespace) -> int:
    try:
        import scipy.stats  # noqa: F401
    except ImportError:
        raise CommandError("the benchmark's statistics need scipy: pip install 'uav-el-assurance[bench]'") from None
    if args.rank_by == "g_star" and args.rank_criterion not in args.criteria:
        args.criteria.append(args.rank_criterion)
    run_dir = Path(args.run) if args.run else _run_campaign(args)
    return _compare(args, run_dir)


def _fit_detectors(args: argparse.Namespace) -> list[str]:
    """Fit the feature-space detectors on ``--fit`` and write their records into ``--out``: their specs."""

    system = assessed(args)
    segmenter = system.segmenter(working_width=system.core.working_width)
    scenes = list(iter_samples(args.fit, require_labels=True))[:args.images]
    if len(scenes) < 5:
        raise CommandError(f"--fit {args.fit}: {len(scenes)} labelled scenes; at least 5 are needed (every 5th is "
                           "held out for the thresholds)")
    kw = {"features": FeatureSettings(core=system.core), "progress": not args.quiet}
    train = collect_candidates(args.fit, segmenter, samples=[s for i, s in enumerate(scenes) if i % 5 != 4],
                               desc="fit scenes", **kw)
    held = collect_candidates(args.fit, segmenter, samples=scenes[4::5], desc="held-out scenes", **kw)
    weights = network_record(segmenter, system.model)
    specs = []
    for family in FAMILIES:
        body = fit_detector_body(family, train, held, labels=labels_of(segmenter), recall=args.recall,
                                 weights=weights)
        path = args.out / f"{family}.json"
        write_json(path, detector_document(body))
        specs.append(f"{family}:model={path}")
        print(f"{family}: fitted on {body['training']['safe_used']} safe candidates; threshold "
              f"{body['threshold']:.4g} ({body['criterion']['note']}); written to {path}")
    return specs


def _run_campaign(args: argparse.Namespace) -> Path:
    """Run the benchmark campaign on ``--data`` into ``--out``/run with ``uav-el campaign`` itself: its checks,
    its signing, its readouts."""

    args.out.mkdir(parents=True, exist_ok=True)
    assess = assessed(args)
    data = assess.data("val", args.data)
    if not Path(data).is_dir():
        raise CommandError(f"{data}: no such folder")
    monitors = list(args.monitors or preset_config("benchmark").monitors)
    if args.fit:
        monitors += _fit_detectors(args)
        if args.monitors:  # the comparison reads the monitors asked for: the fitted ones too
            args.monitors = monitors
    argv = ["--data", str(data), "--out", str(args.out / "run"), "--preset", "benchmark",
            "--monitors", *dict.fromkeys(monitors), "--jobs", str(args.jobs)]
    argv += ["--images", str(args.images)] if args.images else []
    argv += ["--perturbations", *args.perturbations] if args.perturbations else []
    argv += ["--quiet"] if args.quiet else []
    parser = argparse.ArgumentParser(prog="uav-el campaign")
    campaign.add_arguments(parser)
    inner = parser.parse_args(argv)
    inner.system_file, inner.assessed_system = getattr(args, "system_file", None), assess
    code = campaign.run(inner)  # its checks, its signing, its readouts; a bad input raises CommandError
    if code not in (0, 1):
        raise CommandError(f"the benchmark campaign failed (uav-el campaign exit {code})")
    return args.out / "run"


def short_name(name: str) -> str:
    """A configuration's name for tables and the diagram: a fitted file's path shortened to its file name, long
    numbers to 4 significant digits."""
    name = re.sub(r"model=([^,]*)", lambda m: "model=" + Path(m.group(1)).name, name)
    return re.sub(r"=(-?\d+\.\d{5,}(?:e-?\d+)?)", lambda m: f"={float(m.group(1)):.4g}", name)


def _compare(args: argparse.Namespace, run_dir: Path) -> int:
    if not run_dir.is_dir():
        raise CommandError(f"{run_dir}: no such run folder")
    try:
        images, candidates = load_table(run_dir, "images"), load_table(run_dir, "candidates")
        have = scored_monitors(candidates)
        names = [m for m in have if not args.monitors or short_name(m) in map(short_name, _specs(args, have))]
        if not names:
            raise SweepError("no scored monitor of the run to compare")
        table = benchmark_table(images, candidates, names, args.criteria, recall=args.recall,
                                miss_rate=args.miss_rate, confidence=args.confidence)
        measure = block_measure(table, candidates, names, by=args.blocks, measure=args.rank_by,
                                criterion=args.rank_criterion)
    except (SweepError, RunError, ValueError) as exc:
        raise CommandError(f"{run_dir}: {exc}") from None
    table["monitor"] = table["monitor"].map(short_name)
    measure.columns = [short_name(c) for c in measure.columns]
    md, ranking = write_benchmark(args.out, table, measure, blocks=args.blocks, measure=args.rank_by,
                                  deployed=_deployed(args), recall=args.recall, alpha=args.alpha)
    print(md)
    files = "benchmark.md, benchmark.csv, blocks.csv" + (", cd.png" if ranking is not None else "")
    print(f"benchmark of {len(names)} monitors on {run_dir} written to {args.out} ({files})", file=sys.stderr)
    return 0


def _specs(args: argparse.Namespace, have: list[str]) -> list[str]:
    out = []
    for spec in args.monitors:
        try:
            out.append(monitor_name(spec))
        except ValueError:
            out.append(spec)
    return out


def _deployed(args: Any) -> str | None:
    """The system's deployed configuration's name, as its campaign names it (what a better monitor is compared
    with); None when it cannot be told."""

    try:
        spec, card = assessed(args).deployed()
        name = load_calibration(card).spec if card is not None else spec
        return short_name(preset_config("benchmark", deployed=name or None).monitors[0])
    except (ValueError, IndexError, OSError):
        return None
