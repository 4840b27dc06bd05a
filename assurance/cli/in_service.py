"""``uav-el in-service``: flight logs compared with the certification run of their system, judged by its SPIs.

A thin layer over ``assurance.inservice.assess``: it finds the run's system file (the one given must be the run's),
the signing and trusted keys, then writes ``OUT/in-service.json``, ``OUT/in-service.html`` and their signed
statement ``OUT/in-service.dsse.json``. Exit 0: no SPI breached; 1: at least one breached (each named with the claims
it undermines); 2: bad input, logs of another system or configuration, a log whose hash chain is broken, whose
sequence numbers repeat or go back, with a negative time or a record whose reason disagrees with its fields (one line
naming the log and the line); 4: a damaged or unattested run.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from assurance.attest import AttestationError
from assurance.attest.keys import load_signing_key, load_trusted_keys
from assurance.cli.system_options import run_system
from assurance.errors import CommandError

HELP = ("compare flight logs (uav-el land --log, el.flight.flightlog) with the certification run of their system: "
        "drift of "
        "the frame gate's and the monitor's scores, refusal, default and overrun rates, decision times, poses; judge "
        "the system file's [in_service] SPIs; write OUT/in-service.html and a signed OUT/in-service.json; exit 1 on "
        "a breach")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("logs", nargs="+", metavar="LOG",
                   help="flight logs (JSON lines, el.flight.flightlog), read in order")
    p.add_argument("--run", required=True, metavar="RUN", help="the certification campaign run (uav-el campaign --out)")
    p.add_argument("--out", default="reports/in-service", help="output folder (default: reports/in-service/)")
    p.add_argument("--signing-key", metavar="PEM", help="Ed25519 key that signs the report (default: "
                   "$UAV_EL_SIGNING_KEY, else your key file; see uav-el keys)")
    p.add_argument("--trusted-keys", metavar="PEM|DIR", help="keys whose signature of the campaign run is accepted "
                   "(default: $UAV_EL_TRUSTED_KEYS, else your own key)")


def _system(args: argparse.Namespace, run: Path) -> Any:
    """The run's system file (its signed manifest's), or the one given when it is the same file."""
    from assurance.campaign.readouts import read_manifest  # deferred: pulls in pandas; keeps in-service --help light

    system = run_system(args, run)
    recorded = (read_manifest(run).get("system") or {}).get("sha256")
    if recorded and system.sha256 != recorded:
        raise CommandError(f"{system.label}: the run {run} assessed another system file (SHA-256 {recorded[:12]}, "
                           f"this one {system.sha256[:12]}); give the run's system file with --system, or none")
    return system


def _keys(args: argparse.Namespace, out: Path) -> tuple[Any, Any]:
    try:
        return load_signing_key(args.signing_key, outside=out), load_trusted_keys(args.trusted_keys)
    except AttestationError as exc:
        raise CommandError(str(exc)) from None


def _print_log_checks(checks: dict[str, Any]) -> None:
    """What the logs' chains showed that the report states (each chain was verified: a break is refused)."""
    print("hash chain verified: every record follows the line before it, in order")
    for count, what, lines in ((checks["unlogged"], "decision(s) not logged (sequence gaps; the rate SPIs judge them "
                                "both ways)", checks["gaps"]),
                               (checks["clock_back"], "record(s) whose clock goes back", checks["clock_lines"]),
                               (checks["duplicates"], "duplicate record(s) (same frame hash and time) counted once",
                                checks["duplicate_lines"])):
        if count:
            print(f"  {count} {what}; first: {lines[0]}")


def run(args: argparse.Namespace) -> int:
    from assurance.inservice.assess import assess  # deferred: pulls in pandas, scipy; keeps in-service --help light

    run_dir, out = Path(args.run), Path(args.out)
    if not (run_dir / "manifest.json").is_file():
        raise CommandError(f"{run_dir}: not a campaign run (no manifest.json)")
    for log in args.logs:
        if not Path(log).is_file():
            raise CommandError(f"{log}: no such flight log")
    system = _system(args, run_dir)
    key, trusted = _keys(args, out)
    result = assess(args.logs, run_dir, out, system=system, trusted=trusted, key=key)
    doc = result.doc
    print(f"{doc['records']} decision(s) from {len(doc['logs'])} log(s), {doc['damaged']} damaged line(s) passed over; "
          f"compared with {run_dir} ({doc['monitor']})")
    _print_log_checks(doc["log_checks"])
    for spi in doc["spis"]:
        print(f"  {spi['verdict']:>12}  {spi['key']} ({spi['name']}): {spi['evidence']}")
    for claim in doc["undermined"]:
        print(f"undermined: {claim['node']} {claim['title']} (by {', '.join(claim['spis'])})")
    print(f"written: {result.html_path}, {result.json_path}; signed: {result.attestation} (key {key.keyid[:16]})")
    return 1 if result.breaches else 0
