"""The readouts store of a campaign run: a manifest and one Parquet shard per (perturbation, image).

Layout of a run folder::

    RUN/manifest.json            what was evaluated (config, seeds, versions, hashes)
    RUN/shards/<name>/images.parquet       one row per (image, monitor configuration)
    RUN/shards/<name>/candidates.parquet   one row per (candidate, monitor configuration)
    RUN/log.jsonl                one line per campaign invocation

A shard folder is written under a temporary name and renamed into place, so it is either
complete or absent: an interrupted campaign never leaves half a shard, and a re-run skips the
shards that exist.
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pandas as pd

from el.uavid import atomic_write_bytes

FORMAT_VERSION = "uav-el-readouts/1"
SHARDS = "shards"
TABLES = ("images", "candidates")
_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


class RunError(ValueError):
    """A run folder is missing, not a run, or belongs to another campaign."""


def shard_name(perturbation: str, severity: int, key: str) -> str:
    """Folder name of a task's shard, e.g. ``fog-s3__seq00_000012``."""
    return _SAFE.sub("_", f"{perturbation}-s{severity}__{key.replace('/', '_')}")


def init_run(run_dir: Path, manifest: dict[str, Any]) -> None:
    """Create the run folder with its manifest, or check that an existing one is the same campaign."""
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / "manifest.json"
    if path.exists():
        old = json.loads(path.read_text())
        for key in ("format", "config", "data"):
            if old.get(key) != json.loads(json.dumps(manifest.get(key), default=str)):
                raise RunError(f"{run_dir}: holds another campaign (its manifest differs in '{key}'); "
                               "use a new --out folder or delete this one")
        # the same weights, segmenting frames the same way (a run recorded before these keys: the frame alone)
        was, now = old.get("weights") or {}, manifest.get("weights") or {}
        flip = was.get("frame_flip", False if was.get("sha256") else None)  # None: no readable card then
        recorded = {"sha256": was.get("sha256"), "frame_flip": flip,
                    "frame_scales": was.get("frame_scales", None if flip is None else [1.0]),
                    "frame_pooling": was.get("frame_pooling", None if flip is None else "area")}
        for key, before in recorded.items():
            if key in now and before != now[key]:
                raise RunError(f"{run_dir}: holds a campaign run with other weights (weights.{key}: {before} "
                               f"recorded, {now[key]} now); use a new --out folder or delete this one")
        return
    shards = run_dir / SHARDS
    if shards.is_dir() and any(shards.iterdir()):  # e.g. a half-deleted run: its shards may be another campaign's
        raise RunError(f"{run_dir}: has shards but no manifest.json, so they cannot be checked against this "
                       "campaign; use a new --out folder or delete this one")
    shards.mkdir(exist_ok=True)
    atomic_write_bytes(path, json.dumps(manifest, indent=2, sort_keys=True, default=str).encode())


def shard_done(run_dir: Path, name: str) -> bool:
    return (run_dir / SHARDS / name / "images.parquet").is_file()


def write_shard(run_dir: Path, name: str, rows: dict[str, list[dict[str, Any]]]) -> None:
    """Write a shard atomically (temporary folder, then rename)."""
    final = run_dir / SHARDS / name
    if final.exists():
        return
    tmp = Path(tempfile.mkdtemp(dir=run_dir / SHARDS, prefix=f".{name}."))
    try:
        for table in TABLES:
            pd.DataFrame(rows.get(table, [])).to_parquet(tmp / f"{table}.parquet", index=False)
        try:
            tmp.rename(final)
        except OSError:
            if not final.exists():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def read_manifest(run_dir: str | Path) -> dict[str, Any]:
    path = Path(run_dir) / "manifest.json"
    if not path.is_file():
        raise RunError(f"{run_dir}: not a campaign run (no manifest.json)")
    return json.loads(path.read_text())


def load_table(run_dir: str | Path, table: str) -> pd.DataFrame:
    """Concatenate one table over every finished shard, in a fixed (sorted) order."""
    if table not in TABLES:
        raise ValueError(f"unknown table {table!r}; valid: {TABLES}")
    root = Path(run_dir) / SHARDS
    read_manifest(run_dir)
    frames = [pd.read_parquet(p / f"{table}.parquet") for p in sorted(root.iterdir())
              if p.is_dir() and not p.name.startswith(".") and (p / "images.parquet").is_file()]
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True)


def append_log(run_dir: Path, entry: dict[str, Any]) -> None:
    with open(run_dir / "log.jsonl", "a", encoding="utf-8") as f:
        f.write(json.dumps(entry, default=str) + "\n")
