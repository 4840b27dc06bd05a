"""The work of ``uav-el evidence`` (its options: ``assurance.cli.evidence``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from assurance.attest import AttestationError
from assurance.attest.keys import load_trusted_keys
from assurance.campaign import readouts
from assurance.cli.system_options import run_system
from assurance.errors import CommandError, DamagedRunError, RunError
from assurance.evidence import generate
from assurance.evidence.options import ReportOptions
from assurance.evidence.waivers import load_waivers
from assurance.requirements import RegistryError, read_targets_file


def refuse_out_inside_run(out: Path, *runs: Path) -> None:
    """Refuse an output folder that is, or lies inside, a campaign run folder (``runs`` given, or any folder above
    ``out`` holding a run's ``manifest.json`` with its ``shards/`` or shard index): the report writes
    ``results.csv``, ``SHA256SUMS`` and its pages there, which would change the run's files (``--out
    RUN/shards/report`` adds a shard folder the run's index and signature do not know: the run is damaged).
    CommandError (exit 2) naming both folders."""

    target = out.resolve()
    for run_dir in runs:
        if target.is_relative_to(run_dir.resolve()):
            raise CommandError(f"--out {out}: lies inside the campaign run {run_dir}; the report would change the "
                               "run's files: write it outside the run")
    for folder in (target, *target.parents):
        if (folder / "manifest.json").is_file() and ((folder / readouts.SHARDS).is_dir()
                                                     or (folder / readouts.INDEX).is_file()):
            raise CommandError(f"--out {out}: lies inside the campaign run {folder}; the report would change the "
                               "run's files: write it outside the run")


def run(args: argparse.Namespace) -> int:
    if args.baseline_requirements and not args.baseline:
        raise CommandError("--baseline-requirements needs --baseline")
    for flag, value in (("--run", args.run), ("--baseline", args.baseline)):
        if value and not (Path(value) / "manifest.json").is_file():
            raise CommandError(f"{flag} {value}: not a campaign run (no manifest.json)")
    if args.boot < 1:
        raise CommandError("--boot must be >= 1")
    refuse_out_inside_run(Path(args.out), *(Path(r) for r in (args.run, args.baseline) if r))
    if args.waivers:  # read (bounded) before any work: a FIFO or a bad file is refused at once

        load_waivers(args.waivers)
    if args.templates and not Path(args.templates).is_dir():
        raise CommandError(f"--templates {args.templates}: not a folder")
    if args.template_seconds is not None and not 0 < args.template_seconds <= 3600:  # NaN fails both
        raise CommandError(f"--template-seconds {args.template_seconds}: must be in (0, 3600]")
    try:
        trusted = load_trusted_keys(args.trusted_keys)
    except AttestationError as exc:
        raise CommandError(f"{exc}; an auditor gives the signer's public key with --trusted-keys") from None
    try:
        targets = read_targets_file(args.targets) if args.targets else None
        options = ReportOptions(
            requirements=args.requirements, baseline=args.baseline, baseline_requirements=args.baseline_requirements,
            registry=args.registry, targets=targets,
            targets_source=str(Path(args.targets).resolve()) if args.targets else None, strict=args.strict,
            pdf=not args.no_pdf, n_boot=args.boot, waivers=args.waivers, templates=args.templates,
            system=run_system(args, Path(args.run)), trusted=trusted, accepted_deviations=tuple(args.accept_deviation),
            benchmark=args.benchmark, in_service=args.in_service, system_templates=args.system_templates,
            template_seconds=args.template_seconds)
        report = generate(args.run, args.out, options)
    except DamagedRunError:
        raise  # exit 4: the run's readouts fail verification
    except (RegistryError, RunError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    for w in report.warnings:
        print(f"warning: {w}", file=sys.stderr)
    for line in report.summary_lines():
        print(line)
    if report.exit_code:
        failed = [r for r in report.ids("failed") if r not in report.waived]
        undecided = [r for r in report.ids("not verified") if r in report.blocking]
        more = len(report.problems) - 1
        reasons = [report.problems[0] + (f" (and {more} more gate problem(s) above)" if more > 0 else "")
                   ] if report.problems else []
        reasons += (["requirement(s) failed"] if failed else []) + (
            [f"not verified: {', '.join(undecided)}"] if undecided else [])
        if not reasons:
            reasons = ["--strict: no PDF" if report.pdf_error and not report.ids("not verified")
                       else "--strict: not everything verified"]
        print(f"gate: FAILED ({'; '.join(reasons)})")
    else:
        waived = " (failed but waived: " + ", ".join(report.waived) + ")" if report.waived else ""
        print("gate: passed" + waived + (" (some requirements undecidable at this run size; --strict would fail)"
                                         if report.ids("not verified") else ""))
    return report.exit_code
