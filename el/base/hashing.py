"""SHA-256 of bytes and files: how the toolkit identifies inputs, weights, data and reports."""

from __future__ import annotations

import hashlib
from pathlib import Path

from el.base import userfiles


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of a byte string."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | Path, *, chunk: int = 1 << 22, what: str = "file",
                max_bytes: int = userfiles.MAX_HASHED_BYTES, within: str | Path | None = None) -> str:
    """Hex SHA-256 of a file's bytes, read in chunks through the bounded reader (``el.base.userfiles.sha256``): a FIFO,
    a device, a path under ``/proc``, ``/sys`` or ``/dev``, one outside ``within`` or one over ``max_bytes`` (default
    8 GiB, a model's cap) is refused (``UserFileError`` naming it as a ``what``), never read for ever; a missing
    file raises ``FileNotFoundError`` as ``open`` would."""
    return userfiles.sha256(path, what=what, max_bytes=max_bytes, within=within, chunk=chunk)
