"""The campaign's signed statement: every task of the run, every shard file and the manifest, by SHA-256.

``sign_run`` writes ``RUN/campaign.dsse.json`` (an in-toto statement in a DSSE envelope) when a campaign
invocation ends; a resumed campaign signs again over what it then holds. ``check_run_attestation`` verifies
it against trusted keys and recomputes every subject from the files, so a shard copied in, removed or
edited (and re-hashed in its own SHA256SUMS) after signing, a manifest edited, or a task list that is not
the manifest's, is named.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from assurance.attest import AttestationError
from assurance.attest.dsse import read_envelope, write_envelope
from assurance.attest.keys import SigningKey
from assurance.attest.statement import make_statement, open_statement, sign_statement, subject_problems
from assurance.campaign import readouts
from assurance.campaign.integrity import verify_run
from assurance.campaign.label_pin import predicate_fields
from el.base.hashing import sha256_file

if TYPE_CHECKING:
    from assurance.campaign.integrity import RunCheck

ATTESTATION = "campaign.dsse.json"
KIND = "campaign"
MANIFEST = "manifest.json"


def run_subjects(run_dir: str | Path, known: Mapping[str, Mapping[str, str]] | None = None) -> dict[str, str]:
    """What a campaign statement covers, hashed from the files now: the manifest and every shard's data files.
    ``known``: {shard: {file: sha256}} just hashed and verified (``RunCheck.sums``), taken instead of hashing
    those files again."""
    run = Path(run_dir)
    known = known or {}
    out = {MANIFEST: sha256_file(run / MANIFEST)} if (run / MANIFEST).is_file() else {}
    for shard in readouts.shard_dirs(run):
        hashed = known.get(shard.name) or {}
        for f in sorted(p for p in shard.iterdir() if p.is_file()):
            if f.name != readouts.SUMS:  # the sums are a shard's own claim; the statement signs the files
                out[f"{readouts.SHARDS}/{shard.name}/{f.name}"] = hashed.get(f.name) or sha256_file(f)
    return out


def _predicate(run: Path, man: Mapping[str, Any], summary: Mapping[str, Any] | None, check: RunCheck
               ) -> dict[str, Any]:
    order = list(man.get("shard_order") or [])
    done = {p.name for p in readouts.shard_dirs(run)}
    return {
        "tasks": order,
        "missing": [n for n in order if n not in done],
        "run_digest": check.digest,
        "faults": len((summary or {}).get("faults") or []),
        "model_sha256": (man.get("weights") or {}).get("sha256"),
        "monitor_models": man.get("monitor_models") or {},
        "data_sha256": (man.get("data") or {}).get("sha256"),
        "system_sha256": (man.get("system") or {}).get("sha256"),
        **predicate_fields(man),  # the label set and class hierarchy that judged the readouts (label_pin)
        "code": man.get("code") or {},
    }


def sign_run(run_dir: str | Path, key: SigningKey, summary: Mapping[str, Any] | None = None) -> Path:
    """Sign the run as it stands (see the module docstring); returns the attestation's path. Each shard file is
    hashed once: the run's verification hashes the data files, and the statement takes those hashes."""
    run = Path(run_dir)
    man = readouts.read_manifest(run)
    check = verify_run(run)
    stmt = make_statement(run_subjects(run, check.sums), KIND, _predicate(run, man, summary, check))
    path = run / ATTESTATION
    write_envelope(path, sign_statement(stmt, key))
    return path


class UnattestedRunError(readouts.DamagedRunError):
    """A run whose signed statement is missing, untrusted, or does not match its files (exit 4)."""

    def __init__(self, run_dir: str | Path, problems: list[str]) -> None:
        super().__init__(run_dir, problems, headline="not the campaign that was signed", shown=3)


@dataclass
class RunAttestation:
    """What ``check_run_attestation`` found: the signer, the signed predicate, and one line per problem."""

    path: Path
    keyid: str | None = None
    predicate: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def check_run_attestation(run_dir: str | Path, trusted: Mapping[str, Any]) -> RunAttestation:
    """Verify the run's signed statement against ``trusted`` keys and the files as they are now."""
    run = Path(run_dir)
    out = RunAttestation(run / ATTESTATION)
    try:
        stmt, out.keyid = open_statement(read_envelope(out.path), trusted, KIND, where=str(out.path))
    except AttestationError as exc:
        out.problems.append(str(exc))
        return out
    out.predicate = stmt["predicate"]
    out.problems += [f"{run}: {p}" for p in subject_problems(stmt, run_subjects(run))]
    man = readouts.read_manifest(run)
    if list(out.predicate.get("tasks") or []) != list(man.get("shard_order") or []):
        out.problems.append(f"{out.path}: the signed task list is not the manifest's")
    return out
