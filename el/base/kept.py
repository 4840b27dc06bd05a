"""What one command keeps of the files it read (``el.base.userfiles.read_once``): each file's bytes by its identity,
so a file read or hashed again, unchanged, is not opened again (docs/architecture.md section 1.7). The checks a
read makes stay with the reader (``el.base.userfiles``); this module only keeps."""

from __future__ import annotations

import contextlib
import hashlib
import os
import stat
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


def file_key(path: str | Path, *extra: Any) -> tuple[Any, ...] | None:
    """Where and what the regular file at ``path`` is now (real path, device, inode, size, modification time,
    links; ``stat`` only, nothing is opened), with ``extra``: the key under which a reader keeps what it read and
    checked once per command (a changed file has another key). None for anything but a regular file, or when it
    cannot be said: such a path is read (and refused) every time."""
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return None
    if not stat.S_ISREG(info.st_mode):
        return None
    return (os.path.realpath(path), *extra, info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_nlink)


MAX_KEPT_FILE_BYTES = 64 << 20
"""The largest file a command keeps the bytes of (:func:`read_once`): a network, a record, a run's manifest or
table; a data set's frames and larger models are read again when asked again."""
MAX_KEPT_BYTES = 512 << 20
"""All the bytes a command keeps at once (:func:`read_once`)."""
SETTLED_S = 2.0
"""A file changed less than this long ago is not kept (:meth:`Once.key`)."""


@dataclass
class Kept:
    """A file's bytes as one command read them, and their SHA-256 once asked."""

    data: bytes
    digest: str | None = None

    def sha256(self) -> str:
        if self.digest is None:
            self.digest = hashlib.sha256(self.data).hexdigest()
        return self.digest


@dataclass
class Once:
    """What :func:`read_once` keeps: each file's bytes by its identity (:func:`file_key`) and the folder it was
    confined to; a changed file has another identity and is read again."""

    files: dict[tuple[Any, ...], Kept] = field(default_factory=dict)
    held: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    @staticmethod
    def key(p: Path, within: str | Path | None) -> tuple[Any, ...] | None:
        """The file's identity (:func:`file_key`) and its confining folder; None for a file changed in the last
        :data:`SETTLED_S` seconds (a further change may fall within the same tick of the file system's clock, so its
        identity could not tell the two apart): such a file is read each time."""
        key = file_key(p, None if within is None else os.path.realpath(within))
        if key is None or time.time_ns() - key[-2] < SETTLED_S * 1e9:
            return None
        return key

    def keep(self, key: tuple[Any, ...], data: bytes, digest: str | None = None) -> None:
        with self.lock:
            if len(data) <= MAX_KEPT_FILE_BYTES and self.held + len(data) <= MAX_KEPT_BYTES:
                self.files[key] = Kept(data, digest)
                self.held += len(data)


_ONCE: Once | None = None


@contextlib.contextmanager
def read_once() -> Iterator[None]:
    """Within: a file read or hashed again, unchanged, is not opened again; its bytes as first read are given, after
    the same checks on where it lies, its links, its size and whether the auditor protected it (``stat`` only).
    The command line runs each command inside (one command reads one snapshot of each file: the system file's
    gate, card and network, a run's manifest and tables are opened once); a library call outside reads each time.
    Nested scopes share the outermost."""
    global _ONCE
    outer = _ONCE
    if outer is None:
        _ONCE = Once()
    try:
        yield
    finally:
        _ONCE = outer




def current() -> Once | None:
    """The scope of the command now running (None: outside :func:`read_once`)."""
    return _ONCE
