"""Integrity of the evidence chain: the hash of the code, and the verification and digest of a run.

A campaign run's shards carry the SHA-256 of their files (``assurance.campaign.readouts``). ``verify_run``
checks every shard against its SHA256SUMS and the run's shard index and returns the run digest: one
SHA-256 over the shards' hashes in task order. The requirement test session records that digest,
with the hash of the code and of the registry it ran on, so the evidence gate can refuse results
produced on anything else (``assurance.evidence``).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from assurance.campaign import readouts
from el.hashing import sha256_file

ROOT = Path(__file__).resolve().parents[2]
CODE_ROOTS = ("el", "assurance", "tests")
"""What the code hash covers: the flight code, the harness and the tests that verify the requirements."""

__all__ = ["CODE_ROOTS", "RunCheck", "code_sha256", "tree_sha256", "verify_run"]


def tree_sha256(roots: Sequence[Path], *, suffixes: Sequence[str] = (".py", ".yaml", ".yml", ".j2", ".css"),
                base: Path = ROOT) -> tuple[str, int]:
    """SHA-256 over the source files under ``roots`` (relative path and content hash, sorted); (hash, files)."""
    files = sorted(p for r in roots if r.is_dir() for p in r.rglob("*")
                   if p.is_file() and p.suffix in suffixes and "__pycache__" not in p.parts)
    h = hashlib.sha256()
    for p in files:
        h.update(f"{p.relative_to(base).as_posix()}:{sha256_file(p)}\n".encode())
    return h.hexdigest(), len(files)


def code_sha256() -> str:
    """The hash of the code a requirement result is bound to (``CODE_ROOTS`` of this checkout)."""
    return tree_sha256([ROOT / r for r in CODE_ROOTS])[0]


@dataclass
class RunCheck:
    """What ``verify_run`` found: problems (one line per damaged shard), the digest, the shard count."""

    run: Path
    digest: str
    shards: int
    legacy: bool
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def raise_if_damaged(self) -> RunCheck:
        if self.problems:
            raise readouts.DamagedRunError(self.run, self.problems)
        return self


def _order(man: dict, names: set[str]) -> list[str]:
    planned = [n for n in man.get("shard_order") or [] if n in names]
    return planned + sorted(names - set(planned))


def verify_run(run_dir: str | Path) -> RunCheck:
    """Check every shard of a run; the digest covers the verified shards' hashes in task order.

    A run written with hashes (``manifest.integrity``): a shard listed in the index must exist and
    match it; a shard folder not in the index (its worker finished, the runner never recorded it)
    must match its own SHA256SUMS. A legacy run (no hashes): nothing to verify; the digest is taken
    over the files as they are now.
    """
    run = Path(run_dir)
    man = readouts.read_manifest(run)
    present = {p.name for p in readouts.shard_dirs(run)}
    sums: dict[str, dict[str, str]] = {}
    problems: list[str] = []
    legacy = man.get("integrity") != readouts.INTEGRITY
    if legacy:
        for name in present:
            sums[name] = {f: sha256_file(run / readouts.SHARDS / name / f) for f in readouts.shard_files()
                          if (run / readouts.SHARDS / name / f).is_file()}
    else:
        index = readouts.read_index(run)
        for name in sorted(set(index) | present):
            why = readouts.check_shard(run, name, index.get(name))
            if why:
                problems.append(f"shard {name}: {why}")
            else:
                sums[name] = readouts.read_sums(run / readouts.SHARDS / name) or {}
    h = hashlib.sha256()
    for name in _order(man, set(sums)):
        for f, digest in sorted(sums[name].items()):
            h.update(f"{name}/{f}:{digest}\n".encode())
    return RunCheck(run=run, digest=h.hexdigest(), shards=len(sums), legacy=legacy, problems=problems)
