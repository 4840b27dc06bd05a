"""Writing files so that a reader never sees half of one: temp file in the same folder, then rename.

Readouts, reports, cards, weights and scenes are all written through here, with the mode a plain
``open()`` would give them.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def public_mode(mode: int = 0o666) -> int:
    """``mode`` less the process's umask: what ``open()`` would give a new file (0644 under umask 022).

    ``tempfile.mkstemp`` creates files 0600 whatever the umask; files written through it get this mode
    before they are renamed into place, so reports and readouts are readable as any other file.
    """
    mask = os.umask(0o022)  # reading the umask means setting it: put it back at once
    os.umask(mask)
    return mode & ~mask


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write bytes to ``path`` so that a reader never sees a half-written file (mode 0666 less the umask)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, public_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write UTF-8 text atomically (see :func:`atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode("utf-8"))
