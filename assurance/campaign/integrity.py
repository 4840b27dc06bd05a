"""Integrity of the evidence chain: the hash of the code, and the verification and digest of a run.

A campaign run's shards carry the SHA-256 of their files (``assurance.campaign.readouts``). ``verify_run``
checks every shard against its SHA256SUMS and the run's shard index and returns the run digest: one
SHA-256 over the shards' hashes in task order, and names the tasks the manifest plans that left no shard
(``RunCheck.missing``: the evidence gate refuses a report that would not name them). The requirement test
session records that digest, with the hash of the code (``assurance.code_identity``, re-exported here) and of the
registry it ran on, so the evidence gate can refuse results produced on anything else (``assurance.evidence``).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

from assurance.campaign import readouts
from assurance.code_identity import code_sha256, tree_sha256
from el.base.hashing import sha256_file

__all__ = ["RunCheck", "code_sha256", "tree_sha256", "verify_run"]


@dataclass
class RunCheck:
    """What ``verify_run`` found: problems (one line per damaged shard), the digest, the shard count,
    ``sums``: each verified shard's data files as {file: sha256}, as just hashed (``sign_run`` reuses them), and
    ``missing``: the tasks of the manifest's task list (``shard_order``) with no shard folder and no entry in the
    shard index (a shard the index lists but that is gone is a problem instead)."""

    run: Path
    digest: str
    shards: int
    legacy: bool
    problems: list[str] = field(default_factory=list)
    sums: dict[str, dict[str, str]] = field(default_factory=dict, repr=False)
    missing: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def missing_problems(self, shown: int = 5) -> list[str]:
        """One line naming the tasks the manifest plans that have no readouts (empty when none): evidence about
        fewer tasks than the manifest names is an unfinished campaign, or a manifest naming tasks outside the
        data; either way the report must not pass over them (a gate problem)."""
        if not self.missing:
            return []
        names = ", ".join(self.missing[:shown]) + (f", ... {len(self.missing) - shown} more"
                                                    if len(self.missing) > shown else "")
        planned = self.shards + len(self.missing)
        return [f"{self.run}: the manifest names {len(self.missing)} of its {planned} task(s) with no readouts "
                f"({names}): an unfinished campaign (re-run the same uav-el campaign command) or a manifest naming "
                "tasks outside the data"]

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
        present |= set(index)
    missing = [str(n) for n in dict.fromkeys(man.get("shard_order") or []) if n not in present]
    h = hashlib.sha256()
    for name in _order(man, set(sums)):
        for f, digest in sorted(sums[name].items()):
            h.update(f"{name}/{f}:{digest}\n".encode())
    return RunCheck(run=run, digest=h.hexdigest(), shards=len(sums), legacy=legacy, problems=problems,
                    sums=sums, missing=missing)
