"""The last frame a campaign worker decoded, kept for its next task.

``plan`` orders a campaign's tasks scene by scene and the process pool hands a worker a scene's scenarios as one
batch, so a worker decodes each image and label map once instead of once per perturbation (the decode and the
colour lookup were about two fifths of a task's time). An entry is keyed by the file's path, inode, size and
modification time (and, for a label map, the label set and encoding that decoded it), and its arrays are read-only:
a task perturbs a copy, and a stage that wrote into the cached frame would raise rather than change the next task's
pixels.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any

import numpy as np

_LAST: dict[str, tuple[Hashable, Any]] = {}  # kind -> (key, value): one entry of each kind per worker process


def file_key(path: str | Path, *extra: Hashable) -> tuple[Hashable, ...]:
    """What identifies a file's decoded content: its path, inode, size and modification time (and ``extra``); a
    file replaced (written to a temporary file and renamed, as the toolkit writes) is another inode."""
    st = os.stat(path)
    return (str(path), st.st_ino, st.st_size, st.st_mtime_ns, *extra)


def cached(kind: str, key: Hashable, load: Callable[[], Any]) -> Any:
    """``load()``'s value, or the one kept for ``kind`` when its key is ``key``; numpy arrays in it made read-only."""
    hit = _LAST.get(kind)
    if hit is not None and hit[0] == key:
        return hit[1]
    value = load()
    for item in value if isinstance(value, tuple) else (value,):
        if isinstance(item, np.ndarray):
            item.flags.writeable = False
    _LAST[kind] = (key, value)
    return value


def clear() -> None:
    """Forget every kept frame (tests)."""
    _LAST.clear()
