"""``uav-el evidence``: the evidence report of a campaign run, and the gate on the requirement states."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from assurance.attest import AttestationError
from assurance.attest.keys import load_trusted_keys
from assurance.cli.system_options import run_system
from assurance.errors import CommandError, DamagedRunError, RunError

HELP = ("write the evidence report (HTML, PDF, JSON) of a campaign run; exit 1 when a requirement failed, "
        "when the requirement results are not bound to this run, code and registry or contradict the run, or "
        "when a waiver expired, or when a requirement is left not verified for want of evidence (one left undecided "
        "only by the run's size, as the registry's size_limited allows on a small run, fails it with --strict "
        "only); exit 4 for a damaged run")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--run", required=True, help="campaign run folder (uav-el campaign --out)")
    p.add_argument("--out", default="reports", help="output folder (default: reports/)")
    p.add_argument("--requirements", metavar="JSON",
                   help="requirement results of `uav-el verify RUN --out OUT` (default: "
                        "OUT/requirements.json if present; without one every requirement is 'not verified')")
    p.add_argument("--baseline", metavar="RUN0", help="an earlier run: adds a 'what changed' section")
    p.add_argument("--baseline-requirements", metavar="JSON", help="the baseline's requirement results")
    p.add_argument("--registry", metavar="YAML", help="requirement registry (default: assurance/requirements.yaml)")
    p.add_argument("--targets", metavar="JSON", help="requirement targets overriding the registry's parameters (a "
                   "JSON object, the file given to pytest --uav-el-targets); the results must use the same")
    p.add_argument("--waivers", help="accepted deviations: a failed requirement listed there does not fail the "
                   "gate; ignored with --strict (default: the system file's [waivers] file; for the shipped system, "
                   "the shipped assurance/waivers.yaml; a system file without [waivers]: none)")
    p.add_argument("--strict", action="store_true",
                   help="also exit 1 when a requirement is left undecided by the run's size alone (size_limited, on a "
                        "small run), and when the PDF cannot be written; ignores waivers")
    p.add_argument("--no-pdf", action="store_true", help="write the HTML and JSON only")
    p.add_argument("--trusted-keys", metavar="PEM|DIR",
                   help="public keys whose signatures are accepted (a PEM file, or a folder of *.pem/*.pub); default: "
                        "$UAV_EL_TRUSTED_KEYS, else the local signing key's own (uav-el keys)")
    p.add_argument("--templates", metavar="DIR",
                   help="section templates replacing the packaged ones file by file (copy a section_*.html.j2 or "
                        "auditor_*.html.j2 of evidence_templates/ into DIR and edit it); rendered with time and "
                        "memory limits and cleaned to an allow-list of markup; the first page, layout and "
                        "stylesheet are always the toolkit's, and the first page names the folder with its hash "
                        "(default: the packaged templates only)")
    p.add_argument("--template-seconds", type=float, default=None, metavar="S",
                   help="wall-time limit of the supplied templates' rendering, per template (default 60); past it "
                        "the template is refused (exit 2)")
    p.add_argument("--system-templates", action="store_true",
                   help="use the system file's [report] templates as --templates (an applicant's convenience; an "
                        "auditor's report takes none unasked)")
    p.add_argument("--accept-deviation", metavar="NAME=VALUE", action="append", default=[],
                   help="accept a deviation from the certification basis (the packaged registry's) at the value the "
                        "system sets, e.g. unsafe_landing_bound=0.06 or class:road=safe (a class's value is its "
                        "state, safe or forbidden; numbers compare numerically; repeat for several); the report's "
                        "first page records it with both values. A deviation not accepted, or accepted at another "
                        "value, fails the gate; a plain NAME is refused")
    p.add_argument("--benchmark", metavar="DIR", help="a uav-el benchmark --out folder: adds its monitor comparison "
                   "as a section (re-derived from its CSV tables; never moves the gate)")
    p.add_argument("--in-service", metavar="DIR", help="a uav-el in-service --out folder: adds its signed SPI verdicts "
                   "and the claims a breach undermines as a section (never moves the gate)")
    p.add_argument("--boot", type=int, default=2000, help="bootstrap resamples of the results table (default 2000)")


def refuse_out_inside_run(out: Path, *runs: Path) -> None:
    """Refuse an output folder that is, or lies inside, a campaign run folder (``runs`` given, or any folder above
    ``out`` holding a run's ``manifest.json`` with its ``shards/`` or shard index): the report writes
    ``results.csv``, ``SHA256SUMS`` and its pages there, which would change the run's files (``--out
    RUN/shards/report`` adds a shard folder the run's index and signature do not know: the run is damaged).
    CommandError (exit 2) naming both folders."""
    from assurance.campaign import readouts  # deferred: pulls in pandas (readouts); keeps evidence --help light

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
    from assurance.evidence import generate  # deferred: pulls in pandas, scipy; keeps evidence --help light
    from assurance.evidence.options import ReportOptions  # deferred: pandas, scipy; keeps evidence --help light
    from assurance.requirements import (
        RegistryError,
        read_targets_file,
    )  # deferred: pulls in pandas, scipy; keeps evidence --help light

    if args.baseline_requirements and not args.baseline:
        raise CommandError("--baseline-requirements needs --baseline")
    for flag, value in (("--run", args.run), ("--baseline", args.baseline)):
        if value and not (Path(value) / "manifest.json").is_file():
            raise CommandError(f"{flag} {value}: not a campaign run (no manifest.json)")
    if args.boot < 1:
        raise CommandError("--boot must be >= 1")
    refuse_out_inside_run(Path(args.out), *(Path(r) for r in (args.run, args.baseline) if r))
    if args.waivers:  # read (bounded) before any work: a FIFO or a bad file is refused at once
        from assurance.evidence.waivers import load_waivers  # deferred: pandas, scipy; keeps evidence --help light

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
