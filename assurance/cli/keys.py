"""``uav-el keys``: the signing key's fingerprint and public key, to hand to whoever verifies the evidence."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.attest import AttestationError
from assurance.attest.keys import load_signing_key, public_pem
from assurance.errors import CommandError
from assurance.files import atomic_write_text

HELP = ("show the Ed25519 key that signs campaigns and requirement results (its fingerprint; --public prints the "
        "public key an auditor passes to uav-el evidence --trusted-keys); creates your key file on first use")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--signing-key", metavar="PEM", help="the key (default: $UAV_EL_SIGNING_KEY, else your key file)")
    p.add_argument("--public", action="store_true", help="print the public key (PEM)")
    p.add_argument("--out", metavar="FILE", help="write the public key (PEM) to FILE")


def run(args: argparse.Namespace) -> int:
    try:
        key = load_signing_key(args.signing_key)
    except AttestationError as exc:
        raise CommandError(str(exc)) from None
    print(f"signing key: {key.source}")
    print(f"fingerprint (sha256 of the Ed25519 public key): {key.keyid}")
    if args.public:
        print(public_pem(key.public), end="")
    if args.out:
        atomic_write_text(Path(args.out), public_pem(key.public))
        print(f"public key written to {args.out}")
    return 0
