"""Fault-injection cases: forged evidence and a gate that means what it says (rows ``S1``..``S4``).

The workspace's run was signed by the campaign with the local key (``assurance.attest.keys``); each case forges
a copy of it, or the waivers, and returns the ``uav-el evidence`` command that must refuse it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from assurance.attest.keys import create_key, public_pem
from assurance.fault_injection.case import Case, copy_run, reseal_shard


def _evidence(run: Path, out: Path, *extra: object) -> list[str]:
    return ["evidence", "--run", run, "--out", out, "--no-pdf", "--boot", "20", *map(str, extra)]


def _fabricated_run(ws: Path) -> list[str]:
    """One real shard copied under 20 new task names and the shard index deleted: a run that looks bigger."""
    run, shards = copy_run(ws, "run-fabricated")
    for i in range(20):
        shutil.copytree(shards[0], run / "shards" / f"none-s3__seq00_{900000 + i}")
    (run / "shards.json").unlink()
    return _evidence(run, ws / "rep-fabricated")


def _resealed_shard(ws: Path) -> list[str]:
    """A shard's readouts edited and re-hashed in its own SHA256SUMS and the run's index (as a forger would)."""
    run, shards = copy_run(ws, "run-resealed")
    f = shards[0] / "images.parquet"
    f.write_bytes(f.read_bytes() + b"\0")
    reseal_shard(run, shards[0].name)
    return _evidence(run, ws / "rep-resealed")


def _untrusted_key(ws: Path) -> list[str]:
    """The auditor trusts another key than the one that signed the run."""
    other = create_key(ws / "other-key.pem")
    pub = ws / "other-key.pub"
    pub.write_text(public_pem(other.public))
    return _evidence(ws / "run", ws / "rep-untrusted", "--trusted-keys", pub)


def _bogus_waiver(ws: Path) -> list[str]:
    """A waiver of an id the registry lacks, owned by nobody, expiring in 9999."""
    w = ws / "bogus-waivers.yaml"
    w.write_text("waivers:\n  - id: EL-R99\n    reason: none\n    tracked_by: nothing\n    owner: nobody\n"
                 "    expires: 9999-12-31\n")
    return _evidence(ws / "run", ws / "rep-waiver", "--waivers", w)


SIGNING_CASES: tuple[Case, ...] = (
    Case("S1-fabricated-run", "one real shard copied under 20 new task names, shards.json deleted", _fabricated_run,
         4, "not in the signed statement"),
    Case("S2-resealed-shard", "a shard's images.parquet edited and re-hashed in its SHA256SUMS and the index",
         _resealed_shard, 4, "altered after signing"),
    Case("S3-untrusted-key", "evidence --trusted-keys with another key than the campaign's", _untrusted_key, 4,
         "none of them a trusted key"),
    Case("S4-bogus-waiver", "waiver of EL-R99, owner 'nobody', expiring 9999-12-31", _bogus_waiver, 1,
         "not a requirement of the registry", "a waiver names"),
)
