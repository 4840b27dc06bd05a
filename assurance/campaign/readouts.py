"""The readouts store of a campaign run: a manifest and one Parquet shard per (perturbation, image).

Layout of a run folder::

    RUN/manifest.json            what was evaluated (config, seeds, versions, hashes)
    RUN/shards/<name>/images.parquet       one row per (image, monitor configuration)
    RUN/shards/<name>/candidates.parquet   one row per (candidate, monitor configuration)
    RUN/shards/<name>/SHA256SUMS           the SHA-256 of both files, taken when they were written
    RUN/shards.json              the shard index: every finished shard's hashes, recorded by the runner
    RUN/log.jsonl                one line per campaign invocation

A shard folder is written under a temporary name and renamed into place, so it is either
complete or absent: an interrupted campaign never leaves half a shard, and a re-run skips the
shards that exist **and verify**. The hashes make a run tamper-evident: ``check_shard`` names the
file of a shard that no longer matches its SHA256SUMS or the index (altered, truncated, missing),
and ``assurance.campaign.integrity.verify_run`` checks a whole run and computes its digest.

Hashes prove only that a table is the one the runner (or whoever re-sealed and re-signed it) wrote, not that it
is small: a 9 MB ``candidates.parquet`` of 100 million rows fills 8 GB once loaded. Every table is therefore read
through :func:`read_table_file`: the file through the bounded reader (a regular file inside the run, at most
``MAX_TABLE_FILE_BYTES``), then its Parquet footer (rows, columns, decoded bytes) checked against caps derived from
the manifest (:func:`table_caps`) before one row is decoded.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from assurance.errors import DamagedRunError, RunError  # noqa: F401  (re-exported)
from assurance.files import atomic_write_bytes, public_mode
from el.base import userfiles
from el.base.hashing import sha256_file

FORMAT_VERSION = "uav-el-readouts/2"
"""2: shard names carry a digest of the task key (``a b`` and ``a_b`` no longer share one) and the data hash
covers the scenes' ``meta/*.json``. A format-1 run still reads (``uav-el table``, ``evidence``); it cannot be
resumed (``init_run`` says so)."""
OLD_FORMATS = ("uav-el-readouts/1",)
INTEGRITY = "uav-el-shard-sha256/1"
"""Recorded in the manifest (``integrity``) of runs whose shards carry hashes: such a run's shard
without a valid SHA256SUMS is damaged, not a legacy shard."""
SHARDS = "shards"
SUMS = "SHA256SUMS"
INDEX = "shards.json"
MAX_RUN_JSON_BYTES = 64 << 20  # a manifest or shard index of ~250 000 tasks; read bounded (el.base.userfiles)
TABLES = ("images", "candidates")
COLUMNS: dict[str, tuple[str, ...]] = {
    "images": ("key", "sequence", "frame", "perturbation", "severity", "monitor", "fault", "candidates", "action",
               "reason", "selected", "h_default", "h_top", "h_decision", "decision_unsafe", "clearance_decision_m",
               "overhead_s", "default_x", "default_y", "default_r", "width", "height", "height_m", "pitch_deg",
               "roll_deg", "pose_source", "read_s", "perturb_s",
               "segmentation_s", "candidates_s", "monitoring_s", "total_s", "frame_gate_score", "frame_gate_threshold"),
    "candidates": ("key", "sequence", "frame", "perturbation", "severity", "monitor", "rank", "x", "y", "radius_px",
                   "hazard", "hazard_semantic", "hazard_distance", "true_hazard", "true_unsafe", "clearance_m",
                   "accepted", "reason", "seconds", "selected", "examined"),
}
"""Columns every loaded table has (a faulted task's row holds only the task's keys and the fault)."""
_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")

MAX_CANDIDATES_PER_FRAME = 10_000
"""Rows one monitor configuration may add to a table for one task (one frame): the kernel keeps about ``n_star``
(20 by default, at most 1000) representatives, at least one a region; 10 000 is 500 times the default. A task's
shard may hold ``monitors x MAX_CANDIDATES_PER_FRAME`` rows in either table (``images`` holds one a configuration)."""
MAX_RUN_ROWS = 20_000_000
"""Rows one table of a whole run may hold, whatever its manifest says (about 1.6 GB loaded at ~80 bytes a row):
a run of 250 000 tasks (the manifest's own cap, ``MAX_RUN_JSON_BYTES``) x 3 configurations x 20 candidates is
15 million."""
MAX_TABLE_FILE_BYTES = 256 << 20
"""A shard's Parquet file on disk (an honest one is a few kB: one frame's readouts)."""
MAX_TABLE_DECODED_BYTES = 512 << 20
"""A shard's table once decoded, by its footer's uncompressed sizes (a few long strings compress well too)."""
MAX_RUN_DECODED_BYTES = 4 << 30
"""One table of a whole run once decoded, by the footers' uncompressed sizes."""
MAX_TABLE_COLUMNS = 256
"""Columns of a shard's table (the runner writes about 40)."""


def shard_name(perturbation: str, severity: int, key: str) -> str:
    """Folder name of a task's shard, e.g. ``fog-s3__seq00_000012-1f3a9c0b2d4e6f70``: a readable prefix, then 16 hex
    digits of the SHA-256 of the task key, so two tasks never share a folder (``a b`` and ``a_b`` would by
    their prefix alone)."""
    digest = hashlib.sha256(f"{perturbation}|{severity}|{key}".encode()).hexdigest()[:16]
    return _SAFE.sub("_", f"{perturbation}-s{severity}__{key.replace('/', '_')}")[:96] + f"-{digest}"


def init_run(run_dir: Path, manifest: dict[str, Any]) -> None:
    """Create the run folder with its manifest, or check that an existing one is the same campaign."""
    run_dir.mkdir(parents=True, exist_ok=True)
    path = run_dir / "manifest.json"
    if path.exists():
        old = read_manifest(run_dir)  # bounded
        if old.get("format") in OLD_FORMATS:
            raise RunError(f"{run_dir}: a run of readouts format {old['format']} (shard names that could collide, a "
                           f"data hash without meta/*.json); it still reads with `uav-el table` and `uav-el evidence`, "
                           f"but this toolkit writes {FORMAT_VERSION}: run the campaign into a new --out folder")
        for key in ("format", "config", "data"):
            if old.get(key) != json.loads(json.dumps(manifest.get(key), default=str)):
                raise RunError(f"{run_dir}: holds another campaign (its manifest differs in '{key}'); "
                               "use a new --out folder or delete this one")
        was_system, now_system = (old.get("system") or {}).get("sha256"), (manifest.get("system") or {}).get("sha256")
        if was_system and now_system and was_system != now_system:
            raise RunError(f"{run_dir}: holds a campaign run of another system file (SHA-256 {was_system[:12]} "
                           f"then, {now_system[:12]} now); use a new --out folder or delete this one")
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
        # the same fitted monitor models (a run recorded before this key: none, so one with a learned
        # monitor is refused, as its model cannot be shown to be today's)
        was_models, now_models = old.get("monitor_models") or {}, manifest.get("monitor_models") or {}
        if was_models != now_models:
            raise RunError(f"{run_dir}: holds a campaign run whose monitors rest on other fitted models "
                           f"(monitor_models: {was_models or 'not recorded'} then, {now_models} now); use a new "
                           "--out folder or delete this one")
        was_files, now_files = old.get("model_files"), manifest.get("model_files") or {}
        changed = sorted(f for f in {*(was_files or {}), *now_files} if (was_files or {}).get(f) != now_files.get(f))
        if was_files is not None and changed:
            raise RunError(f"{run_dir}: holds a campaign run made with other model files ({changed[0]}"
                           + (f" and {len(changed) - 1} more" if len(changed) > 1 else "")
                           + " differ); use a new --out folder or delete this one")
        return
    shards = run_dir / SHARDS
    if shards.is_dir() and any(shards.iterdir()):  # e.g. a half-deleted run: its shards may be another campaign's
        raise RunError(f"{run_dir}: has shards but no manifest.json, so they cannot be checked against this "
                       "campaign; use a new --out folder or delete this one")
    shards.mkdir(exist_ok=True)
    atomic_write_bytes(path, json.dumps(manifest, indent=2, sort_keys=True, default=str).encode())


def shard_files() -> tuple[str, ...]:
    """The data files of a shard, in the order their hashes are listed."""
    return tuple(f"{t}.parquet" for t in TABLES)


def read_sums(shard_dir: Path) -> dict[str, str] | None:
    """A shard's SHA256SUMS as {file: sha256}; None when it is missing or malformed."""
    try:  # a regular file of a few lines (a FIFO or a device in a run is refused, never read)
        lines = userfiles.read_text(shard_dir / SUMS, what="shard's SHA256SUMS", max_bytes=1 << 16).splitlines()
    except userfiles.UserFileError:
        return None
    out: dict[str, str] = {}
    for line in lines:
        parts = line.split("  ", 1)
        if len(parts) != 2 or not re.fullmatch(r"[0-9a-f]{64}", parts[0]):
            return None
        out[parts[1]] = parts[0]
    return out if set(out) == set(shard_files()) else None


def check_shard(run_dir: str | Path, name: str, expected: Mapping[str, str] | None = None) -> str | None:
    """Why a shard fails verification (one phrase naming the file), or None when it verifies.

    Every data file must hash to its SHA256SUMS line and, when ``expected`` (the index's entry) is
    given, the SHA256SUMS must be the index's.
    """
    folder = Path(run_dir) / SHARDS / name
    if not folder.is_dir():
        return "shard folder missing"
    sums = read_sums(folder)
    if sums is None:
        return f"{SUMS} missing or malformed"
    for f in shard_files():
        path = folder / f
        if not path.is_file():
            return f"{f} missing"
        try:  # a regular file inside the run, never /proc or a device through a link
            digest = sha256_file(path, what="readouts table", max_bytes=MAX_TABLE_FILE_BYTES, within=run_dir)
        except (OSError, userfiles.UserFileError) as exc:
            return f"{f} unreadable ({exc})"
        if digest != sums[f]:
            return f"{f} differs from its {SUMS} (altered or truncated)"
    if expected is not None and dict(expected) != sums:
        diff = sorted(f for f in shard_files() if expected.get(f) != sums.get(f))
        return f"{SUMS} differs from the run's shard index ({', '.join(diff)})"
    return None


def has_integrity(run_dir: str | Path) -> bool:
    """Whether the run was written with shard hashes (its manifest says so)."""
    try:
        return read_manifest(run_dir).get("integrity") == INTEGRITY
    except (RunError, ValueError):
        return False


def shard_done(run_dir: Path, name: str) -> bool:
    """A shard is done when it verifies (a run written before shard hashes: when its tables read)."""
    folder = Path(run_dir) / SHARDS / name
    if not (folder / "images.parquet").is_file():
        return False
    if (folder / SUMS).exists() or has_integrity(run_dir):
        return check_shard(run_dir, name) is None
    try:  # a legacy shard: done if both tables read (a truncated file does not)
        caps = table_caps(read_manifest(run_dir))
        for f in shard_files():
            read_table_file(folder / f, max_rows=caps[0])
    except Exception:
        return False
    return True


def write_shard(run_dir: Path, name: str, rows: dict[str, list[dict[str, Any]]]) -> dict[str, str] | None:
    """Write a shard atomically (temporary folder, then rename), its SHA256SUMS last; returns the
    hashes {file: sha256} (None when a finished shard of that name was already there)."""
    final = run_dir / SHARDS / name
    if final.exists():
        return None
    tmp = Path(tempfile.mkdtemp(dir=run_dir / SHARDS, prefix=f".{name}."))
    try:
        sums = {}
        for table in TABLES:
            path = tmp / f"{table}.parquet"
            pd.DataFrame(rows.get(table, [])).to_parquet(path, index=False)
            os.chmod(path, public_mode(0o666))
            sums[path.name] = sha256_file(path)
        (tmp / SUMS).write_text("".join(f"{h}  {f}\n" for f, h in sums.items()), encoding="utf-8")
        os.chmod(tmp / SUMS, public_mode(0o666))
        os.chmod(tmp, public_mode(0o777))
        try:
            tmp.rename(final)
        except OSError:
            if not final.exists():
                raise
            return None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return sums


def read_index(run_dir: str | Path) -> dict[str, dict[str, str]]:
    """The run's shard index {shard: {file: sha256}} (empty when there is none yet)."""
    path = Path(run_dir) / INDEX
    if not path.is_file():
        return {}
    try:
        doc = json.loads(userfiles.read_text(path, what="shard index", max_bytes=MAX_RUN_JSON_BYTES))
        shards = doc["shards"]
        if not isinstance(shards, dict):
            raise TypeError
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DamagedRunError(run_dir, [f"{INDEX}: unreadable shard index ({exc})"]) from None
    return {str(k): dict(v) for k, v in shards.items()}


def set_aside_index(run_dir: str | Path) -> str | None:
    """Move an unreadable shard index to ``RUN/damaged/`` so the runner rebuilds it from the shards that verify
    against their own SHA256SUMS; returns the line saying so (None when the index reads or is absent)."""
    try:
        read_index(run_dir)
        return None
    except DamagedRunError as exc:
        why = exc.problems[0]
    aside = Path(run_dir) / "damaged"
    aside.mkdir(exist_ok=True)
    k = 0
    while (aside / f"{INDEX}.{k}").exists():
        k += 1
    (Path(run_dir) / INDEX).rename(aside / f"{INDEX}.{k}")
    return f"{why}: set aside as damaged/{INDEX}.{k}; rebuilt from the shards' own {SUMS}"


def record_shards(run_dir: str | Path, hashes: Mapping[str, Mapping[str, str] | None]) -> None:
    """Add (or, with None, remove) shards' hashes to the run's shard index (the runner's process only)."""
    index = read_index(run_dir)
    for name, h in hashes.items():
        if h is None:
            index.pop(name, None)
        else:
            index[name] = dict(h)
    doc = {"format": INTEGRITY, "shards": dict(sorted(index.items()))}
    atomic_write_bytes(Path(run_dir) / INDEX, (json.dumps(doc, indent=1) + "\n").encode())


def read_manifest(run_dir: str | Path) -> dict[str, Any]:
    path = Path(run_dir) / "manifest.json"
    if not path.is_file():
        raise RunError(f"{run_dir}: not a campaign run (no manifest.json)")
    try:
        man = userfiles.read_json(path, what="run manifest", max_bytes=MAX_RUN_JSON_BYTES)
    except (userfiles.UserFileError, UnicodeDecodeError) as exc:
        raise RunError(f"{path}: a damaged run manifest ({exc})") from None
    if not isinstance(man, dict):
        raise RunError(f"{path}: a damaged run manifest (not a JSON object)")
    return man


def core_hazard(images: pd.DataFrame) -> pd.Series:
    """Per image row, the true hazard of the core model's choice ``c~``: its top candidate, or the default
    area when it found none (``h_top`` is NaN then), as ``assurance.analysis.metrics.ImageReadout.h_core``."""
    return images["h_top"].fillna(images["h_default"])


def table_caps(manifest: Mapping[str, Any]) -> tuple[int, int]:
    """(rows of one shard's table, rows of one table of the whole run) a run's tables may hold: a task (a shard)
    ``configurations x MAX_CANDIDATES_PER_FRAME``, the run its tasks (the larger of the manifest's ``tasks`` and
    its task list) times that, both at most ``MAX_RUN_ROWS``."""
    config = manifest.get("config") if isinstance(manifest.get("config"), Mapping) else {}
    monitors = config.get("monitors") if isinstance(config.get("monitors"), list | tuple) else []
    declared = manifest.get("tasks")
    order = manifest.get("shard_order")
    tasks = max(declared if isinstance(declared, int) and not isinstance(declared, bool) else 0,
                len(order) if isinstance(order, list) else 0, 1)
    per_task = max(1, len(monitors)) * MAX_CANDIDATES_PER_FRAME
    return min(per_task, MAX_RUN_ROWS), min(tasks * per_task, MAX_RUN_ROWS)


def read_table_file(path: str | Path, *, max_rows: int, within: str | Path | None = None,
                    max_decoded: int = MAX_TABLE_DECODED_BYTES) -> pd.DataFrame:
    """One shard's Parquet table, read bounded: the file through ``el.base.userfiles`` (a regular file, inside
    ``within`` when given, at most ``MAX_TABLE_FILE_BYTES``), then refused (``RunError`` naming it) before any row
    is decoded when its footer declares more than ``max_rows`` rows, ``MAX_TABLE_COLUMNS`` columns or
    ``max_decoded`` bytes uncompressed."""
    data, _, _ = _checked_table(Path(path), max_rows=max_rows, within=within, max_decoded=max_decoded)
    return _decode_table(Path(path), data, max_rows)


def _checked_table(path: Path, *, max_rows: int, within: str | Path | None, max_decoded: int
                   ) -> tuple[bytes, int, int]:
    """(the file's bytes, the rows and the decoded bytes its footer declares), refused as ``read_table_file``
    says; nothing decoded yet."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        data = userfiles.read_bytes(path, what="readouts table", max_bytes=MAX_TABLE_FILE_BYTES, within=within)
    except userfiles.UserFileError as exc:
        raise RunError(str(exc)) from None
    try:
        meta = pq.ParquetFile(pa.BufferReader(data)).metadata
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise RunError(f"{path}: not a readable Parquet table ({exc})") from None
    rows = max(meta.num_rows, sum(meta.row_group(i).num_rows for i in range(meta.num_row_groups)))
    decoded = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
    if rows > max_rows:
        raise RunError(f"{path}: {rows} rows exceeds the limit of {max_rows} rows for one task's readouts "
                       f"(its monitor configurations x {MAX_CANDIDATES_PER_FRAME} candidates); refused before "
                       "it is loaded")
    if meta.num_columns > MAX_TABLE_COLUMNS:
        raise RunError(f"{path}: {meta.num_columns} columns exceeds the limit of {MAX_TABLE_COLUMNS} for a readouts "
                       "table")
    if decoded > max_decoded:
        raise RunError(f"{path}: {decoded} bytes once decoded exceeds the limit of {max_decoded} bytes for one "
                       "task's readouts; refused before it is loaded")
    return data, rows, decoded


def _decode_table(path: Path, data: bytes, max_rows: int) -> pd.DataFrame:
    import pyarrow as pa

    try:
        frame = pd.read_parquet(io.BytesIO(data))
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise RunError(f"{path}: not a readable Parquet table ({exc})") from None
    if len(frame) > max_rows:  # a footer that under-declared its rows
        raise RunError(f"{path}: {len(frame)} rows exceeds the limit of {max_rows} rows for one task's readouts")
    return frame


def load_table(run_dir: str | Path, table: str) -> pd.DataFrame:
    """Concatenate one table over every finished shard, in a fixed (sorted) order. Each shard is read bounded
    (:func:`read_table_file`: a regular file inside the run, its footer checked before a row is decoded), and the
    rows and decoded bytes of the shards so far are checked against the run's caps (:func:`table_caps`,
    ``MAX_RUN_DECODED_BYTES``) before the next is decoded: ``RunError`` naming the run past either."""
    if table not in TABLES:
        raise ValueError(f"unknown table {table!r}; valid: {TABLES}")
    per_shard, per_run = table_caps(read_manifest(run_dir))
    root = Path(run_dir).resolve()
    frames, rows, decoded = [], 0, 0
    for p in (d / f"{table}.parquet" for d in shard_dirs(run_dir) if (d / "images.parquet").is_file()):
        data, n, size = _checked_table(p, max_rows=per_shard, within=root, max_decoded=MAX_TABLE_DECODED_BYTES)
        rows, decoded = rows + n, decoded + size
        if rows > per_run:
            raise RunError(f"{run_dir}: its {table} tables hold more than {per_run} rows together, the limit for the "
                           "run's tasks and monitor configurations; refused before they are loaded")
        if decoded > MAX_RUN_DECODED_BYTES:
            raise RunError(f"{run_dir}: its {table} tables take more than {MAX_RUN_DECODED_BYTES} bytes once "
                           "decoded; refused before they are loaded")
        frame = _decode_table(p, data, per_shard)
        if len(frame):
            frames.append(frame)
    if not frames:
        return pd.DataFrame(columns=list(COLUMNS[table]))
    df = pd.concat(frames, ignore_index=True)
    missing = [c for c in COLUMNS[table] if c not in df.columns]
    return df.assign(**dict.fromkeys(missing, float("nan"))) if missing else df


def image_size(row: Mapping[str, Any]) -> tuple[int, int]:
    """The input image's (width, height) of an images-table row: its ``width`` / ``height`` readouts or, in a
    run recorded before them, worked back from the default disc (centred, tangent to the bottom edge)."""
    w, h = row.get("width"), row.get("height")
    if w is not None and h is not None and not (pd.isna(w) or pd.isna(h)):
        return int(w), int(h)
    return (int(round(2 * float(row["default_x"]))),
            int(round(float(row["default_y"]) + float(row["default_r"]))))


def input_size(images: pd.DataFrame) -> tuple[int, int] | None:
    """The input size (W, H) of a run's first evaluated (non-faulted) image; None when there is none."""
    ok = images[images["fault"].fillna("") == ""] if len(images) else images
    return image_size(ok.iloc[0]) if len(ok) else None


def shard_dirs(run_dir: str | Path) -> list[Path]:
    """The run's shard folders (not the temporary ones), sorted by name."""
    root = Path(run_dir) / SHARDS
    if not root.is_dir():
        return []
    return sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))


def append_log(run_dir: Path, entry: dict[str, Any]) -> None:
    with open(run_dir / "log.jsonl", "a", encoding="utf-8") as f:
        f.write(json.dumps(entry, default=str) + "\n")
