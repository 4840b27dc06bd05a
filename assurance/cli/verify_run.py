"""The work of ``uav-el verify`` (its options: ``assurance.cli.verify``)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

from assurance.attest import AttestationError
from assurance.attest.keys import load_signing_key, load_trusted_keys
from assurance.campaign.attestation import UnattestedRunError, check_run_attestation
from assurance.campaign.readouts import read_manifest
from assurance.cli.system_options import run_system
from assurance.code_identity import install_root
from assurance.errors import CommandError
from assurance.evidence.gate import weakening_problems
from assurance.requirements import RegistryError, load_registry, read_targets_file
from assurance.requirements.attestation import sign_session_results
from assurance.requirements.suite import SUITE_DIR
from assurance.system import default_system

log = logging.getLogger(__name__)


def pytest_args(args: argparse.Namespace, out: Path) -> list[str]:
    """The pytest command line of the session (what ``uav-el verify`` runs)."""
    argv = [str(SUITE_DIR), *[str(Path(t).resolve()) for t in args.tests], "-m", "requirements",
            "-p", "no:cacheprovider", "--rootdir", str(install_root()),
            "--uav-el-run", str(Path(args.run).resolve()), "--uav-el-report", str(out / "requirements.json"),
            "--junitxml", str(out / "junit.xml")]
    if args.registry:
        argv += ["--uav-el-registry", args.registry]
    if args.targets:
        argv += ["--uav-el-targets", args.targets]
    if args.keyword:
        argv += ["-k", args.keyword]
    verbose = getattr(args, "verbose", 0) or 0
    quiet = getattr(args, "quiet", 0) or 0
    argv += ["-v"] * verbose if verbose else ["-q"] * (1 + quiet)
    return argv


def _judge_the_runs_system(args: argparse.Namespace, run: Path) -> None:
    """Without a system file given, the system judged is the run's own, as its signed manifest records it (also over
    a ``uav-el.toml`` in the working directory; ``evidence`` takes the same): its waivers are the ones the results
    are signed with, never the shipped system's. Says which system it judges."""
    given = getattr(args, "system_file", None)
    system = run_system(args, run)  # says which system it judges
    if system is not given and not system.default:
        args.system_file, args.system_from_run = system, True


def _check_system(args: argparse.Namespace, run: Path) -> None:
    """A system file given (or found) must be the one the run assessed: the results are judged on the run's."""
    system = getattr(args, "system_file", None)
    if system is None or system.default:
        return

    recorded = (read_manifest(run).get("system") or {}).get("sha256")  # bounded: the applicant's run
    if recorded and recorded != system.sha256:
        raise CommandError(f"{system.label}: the run {run} assessed another system file (SHA-256 {recorded[:12]}, "
                           f"this one {system.sha256[:12]}); give the run's system file with --system")


def _warn_weaker(args: argparse.Namespace) -> None:
    """A registry or targets weaker than the system's are judged, but the evidence gate will refuse them: say so
    now, naming each parameter."""
    if not (args.registry or args.targets):
        return

    system = getattr(args, "system_file", None) or default_system()
    try:
        targets = read_targets_file(args.targets) if args.targets else system.targets()
        reg = load_registry(args.registry, targets=targets, targets_source=args.targets or system.label)
    except (RegistryError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    for line in weakening_problems(reg, system):
        print(f"warning: {line} (the evidence gate will fail)", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    import pytest

    run_dir = Path(args.run)
    if not (run_dir / "manifest.json").is_file():
        raise CommandError(f"{run_dir}: not a campaign run (no manifest.json)")
    for t in args.tests:
        if not Path(t).exists():
            raise CommandError(f"--tests {t}: no such file or folder")
    _judge_the_runs_system(args, run_dir)
    _check_system(args, run_dir)
    _warn_weaker(args)
    key, campaign = _signer_and_campaign(args, run_dir)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    argv = pytest_args(args, out.resolve())
    log.info("pytest %s", " ".join(argv))
    rc = int(pytest.main(argv))
    if rc == pytest.ExitCode.INTERRUPTED:
        raise CommandError("the requirement test session stopped: a test could not be collected (or the session "
                           "was interrupted), see above; nothing is signed, and no result of it is evidence")
    if rc in (pytest.ExitCode.USAGE_ERROR, pytest.ExitCode.INTERNAL_ERROR):
        raise CommandError(f"the requirement test session stopped (pytest exit code {rc}); see above")
    if rc == pytest.ExitCode.NO_TESTS_COLLECTED:
        raise CommandError("no requirement test was collected (a -k expression that matches nothing?)")
    signed = _sign(args, run_dir, out, key, campaign)
    print(f"signed: {signed} (key {key.keyid[:16]}, {key.source})")
    system = getattr(args, "system_file", None)
    given = (f" --system {system.label}" if system is not None and not system.default
             and not getattr(args, "system_from_run", False) else "")
    print(f"requirement results: {out / 'requirements.json'}, {out / 'junit.xml'} "
          f"(next: uav-el evidence --run {args.run} --out {args.out}{given})")
    return 1 if rc == pytest.ExitCode.TESTS_FAILED else 0


def _signer_and_campaign(args: argparse.Namespace, run: Path) -> tuple[Any, Any]:
    """The signing key, and the run's signed campaign statement verified against the trusted keys (exit 4 when
    it does not verify: results about a run nobody trusted signing are not evidence)."""

    try:
        key = load_signing_key(args.signing_key, outside=run)
        trusted = load_trusted_keys(args.trusted_keys)
    except AttestationError as exc:
        raise CommandError(str(exc)) from None
    campaign = check_run_attestation(run, trusted)
    if not campaign.ok:
        raise UnattestedRunError(run, campaign.problems)
    return key, campaign


def _sign(args: argparse.Namespace, run: Path, out: Path, key: Any, campaign: Any) -> Path:
    """Sign the results with what they were judged on (the pins the evidence step compares)."""

    if not (out / "requirements.json").is_file():
        raise CommandError(f"{out / 'requirements.json'}: the test session wrote no results")
    system = getattr(args, "system_file", None) or default_system()
    return sign_session_results(run, out, key, waivers=system.waivers(args.waivers),
                                extra={"campaign_signed_by": campaign.keyid, "keyword": args.keyword,
                                       "tests": [str(t) for t in args.tests]})
