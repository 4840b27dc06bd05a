"""Find and load the system a command assesses: ``--system FILE``, else ``uav-el.toml`` here, else the default."""

from __future__ import annotations

import logging
import os
from collections.abc import Collection
from pathlib import Path

from assurance.system.checks import check_system
from assurance.system.loader import SYSTEM_FILE, SystemFile, default_system, read_system

log = logging.getLogger(__name__)


def load_system(path: str | Path, *, writes: Collection[str] = ()) -> SystemFile:
    """Read, validate and check a system file (``SystemFileError`` naming the file, key, value, allowed); ``writes``:
    keys naming a file the command writes, which need not be there yet (``checks.check_system``)."""
    system = read_system(path)
    check_system(system, writes=writes)
    return system


def find_system(explicit: str | Path | None = None, cwd: str | Path | None = None, *,
                writes: Collection[str] = ()) -> SystemFile:
    """The system a command assesses: ``--system FILE``, else ``uav-el.toml`` in the working directory, else the
    embedded default. Anything named ``uav-el.toml`` in the working directory is the system file: one that is not a
    regular file (a FIFO, a device, a folder, a dangling link) is refused by the reader's line naming it, not passed
    over for the default (which would assess a system other than the one the applicant put there)."""
    if explicit is not None:
        system = load_system(explicit, writes=writes)
    else:
        here = Path(cwd or Path.cwd()) / SYSTEM_FILE
        found = os.path.lexists(here)
        system = load_system(here, writes=writes) if found else default_system()
        if found:
            log.info("system file found in the working directory: %s", here)
    log.info("system assessed: %s (SHA-256 %s)", system.label, system.sha256[:12] or "-")
    return system
