"""Per-frame poses: the ``seqNN/poses.csv`` sidecar exported from a flight log, and the pose policy.

The sidecar holds one line per frame, ``frame,height_m,pitch_deg[,roll_deg]``, ``frame`` the stem of
``seqNN/Images/<frame>.png``. Synthetic scenes also record the pose they were rendered at in their
meta JSON. A campaign's pose policy (docs/architecture.md section 1.4, seam 3) says which pose plans
each frame:

- ``nominal``: the configured nominal pose for every frame (per-frame poses ignored; the default);
- ``sidecar``: the frame's own pose when it has one (sidecar, else the synthetic scene's meta), else nominal;
- ``required``: the frame's own pose; a frame without one is a fault of its task, never a guess.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from assurance.files import atomic_write_bytes
from el.base import userfiles
from el.base.errors import DataError
from el.geometry.camera import HEIGHT_M, MAX_ROLL_DEG, PITCH_DEG, Pose

POSES_FILE = "poses.csv"
POLICIES = ("nominal", "sidecar", "required")
COLUMNS = ("frame", "height_m", "pitch_deg")
ROLL = "roll_deg"
NOMINAL, FRAME, META = "nominal", "frame", "meta"  # where a frame's pose came from


@dataclass(frozen=True)
class FramePose:
    """One frame's pose from the flight log: the planner's ``Pose`` and the roll (degrees, not modelled)."""

    pose: Pose
    roll_deg: float = 0.0


def check_policy(policy: object) -> str:
    """``policy`` when it is one of POLICIES; ValueError naming it and the allowed values."""
    if policy not in POLICIES:
        raise ValueError(f"poses must be one of {', '.join(POLICIES)}, got {policy!r}")
    return str(policy)


def read_poses(path: str | Path) -> dict[str, FramePose]:
    """Read a poses sidecar: {frame: FramePose}. DataError naming file, line, column and value for any problem
    (unknown or missing header columns, a value that is not a number or out of range, a duplicate frame).

    The file is read through ``el.base.userfiles`` (a regular file of at most ``MAX_POSES_BYTES``: a FIFO or a device
    is refused before any read) and its rows are parsed one at a time, so memory stays a small multiple of the
    file's size (a 200 MB sidecar read whole into a list of rows took 3.5 GB)."""
    path = Path(path)
    try:
        text = userfiles.read_text(path, what="poses file", max_bytes=userfiles.MAX_POSES_BYTES,
                                   encoding="utf-8-sig")
    except userfiles.UserFileError as exc:
        raise DataError(str(exc)) from None
    rows = csv.reader(io.StringIO(text))
    first = next(rows, None)
    if first is None:
        raise DataError(f"{path}: empty poses file (expected a header {','.join(COLUMNS)}[,{ROLL}])")
    header = [h.strip() for h in first]
    if header not in (list(COLUMNS), [*COLUMNS, ROLL]):
        raise DataError(f"{path}:1: header must be {','.join(COLUMNS)} or {','.join(COLUMNS)},{ROLL}, "
                        f"got {','.join(header)!r}")
    out: dict[str, FramePose] = {}
    for line, row in enumerate(rows, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise DataError(f"{path}:{line}: {len(row)} column(s), the header has {len(header)}")
        frame = row[0].strip()
        if not frame or "/" in frame or "\\" in frame:
            raise DataError(f"{path}:{line}: column frame: {frame!r} is not an image stem")
        if frame in out:
            raise DataError(f"{path}:{line}: column frame: {frame!r} appears twice")
        height = _number(path, line, "height_m", row[1], HEIGHT_M, "m")
        pitch = _number(path, line, "pitch_deg", row[2], PITCH_DEG, "degrees")
        roll = _number(path, line, ROLL, row[3], (-MAX_ROLL_DEG, MAX_ROLL_DEG), "degrees") if len(row) > 3 else 0.0
        out[frame] = FramePose(Pose(height_m=height, pitch_deg=pitch), roll)
    return out


def _number(path: Path, line: int, column: str, text: str, bounds: tuple[float, float], unit: str) -> float:
    try:
        value = float(text.strip())
    except ValueError:
        raise DataError(f"{path}:{line}: column {column}: {text!r} is not a number") from None
    lo, hi = bounds
    if not (math.isfinite(value) and lo <= value <= hi):
        raise DataError(f"{path}:{line}: column {column}: {text.strip()!r} must lie in [{lo:g}, {hi:g}] {unit}")
    return value


def write_poses(path: str | Path, poses: Mapping[str, FramePose | Pose]) -> None:
    """Write a poses sidecar (frames sorted; ``roll_deg`` only when some frame has a roll), atomically."""
    items = {k: (v if isinstance(v, FramePose) else FramePose(v)) for k, v in sorted(poses.items())}
    roll = any(fp.roll_deg for fp in items.values())
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*COLUMNS, ROLL] if roll else COLUMNS)
    for frame, fp in items.items():
        row = [frame, repr(float(fp.pose.height_m)), repr(float(fp.pose.pitch_deg))]
        w.writerow([*row, repr(float(fp.roll_deg))] if roll else row)
    atomic_write_bytes(Path(path), buf.getvalue().encode("utf-8"))


def sequence_poses(seq_dir: Path, frames: set[str]) -> dict[str, FramePose]:
    """The sidecar of a sequence folder ({} without one); a frame it names that has no image is a DataError, and so
    is a sidecar that is not a regular file (a FIFO, a device: refused by ``read_poses``, not silently ignored)."""
    path = seq_dir / POSES_FILE
    if not path.exists() and not path.is_symlink():
        return {}
    poses = read_poses(path)
    unknown = sorted(set(poses) - frames)
    if unknown:
        raise DataError(f"{path}: frame {unknown[0]!r} has no image in {seq_dir / 'Images'}"
                        + (f" ({len(unknown)} unknown frames)" if len(unknown) > 1 else ""))
    return poses


def read_meta(path: str | Path) -> dict[str, Any]:
    """A scene's meta JSON (``meta/*.json``: pose, seed, split, style, world model), read through the bounded
    reader (``el.base.userfiles``: a regular file of at most ``MAX_META_BYTES``, never under ``/proc``, ``/sys`` or
    ``/dev``): data folders are not signed, so one may be a FIFO or a link to ``/dev/zero``. ``FileNotFoundError``
    when there is none; ``ValueError`` (``UserFileError``) naming the file when it is refused, not JSON or not an
    object."""
    p = Path(path)
    if not p.exists() and not p.is_symlink():
        raise FileNotFoundError(f"{p}: no such file")
    doc = userfiles.read_json(p, what="scene meta file", max_bytes=userfiles.MAX_META_BYTES)
    if not isinstance(doc, dict):
        raise userfiles.UserFileError(f"{p}: a scene meta file holds a JSON object")
    return doc


def meta_pose(meta_path: Path) -> Pose | None:
    """The pose a synthetic scene was rendered at (its meta JSON), None when there is no meta file."""
    if not meta_path.is_file():  # a FIFO or a device there is not a meta file, never read
        return None
    try:  # read bounded: a link to /proc, an oversized file is refused, naming it
        pose = read_meta(meta_path)["pose"]
        return Pose(height_m=float(pose["height_m"]), pitch_deg=float(pose["pitch_deg"]))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DataError(f"{meta_path}: no readable pose in the meta file: {exc}") from None


def frame_pose(sample: object, policy: str, nominal: Pose) -> tuple[Pose, float, str]:
    """(pose, roll_deg, source) that plans a sample's frame under ``policy``; source is nominal, frame or meta.

    ``sample`` is an ``assurance.dataio.uavid.Sample``: ``pose`` and ``roll_deg`` from its sequence's
    sidecar (``poses_path``). A sequence without a sidecar falls back on the pose a synthetic scene's meta
    records. Under ``required`` a frame without a pose is a DataError naming the sidecar that lacks it."""
    check_policy(policy)
    if policy == "nominal":
        return nominal, 0.0, NOMINAL
    own = getattr(sample, "pose", None)
    if own is not None:
        return own, float(getattr(sample, "roll_deg", 0.0) or 0.0), FRAME
    sidecar = getattr(sample, "poses_path", None)
    if sidecar is None:
        meta = meta_pose(sample.meta_path())  # type: ignore[attr-defined]
        if meta is not None:
            return meta, 0.0, META
    if policy == "required":
        where = sidecar or sample.image_path.parent.parent / POSES_FILE  # type: ignore[attr-defined]
        raise DataError(f"{where}: no pose for frame {sample.frame!r} (poses required: "  # type: ignore[attr-defined]
                        "give it a line frame,height_m,pitch_deg)")
    return nominal, 0.0, NOMINAL
