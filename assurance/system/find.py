"""Find and load the system a command assesses: ``--system FILE``, else ``uav-el.toml`` here, else the default."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from assurance.system.checks import check_system
from assurance.system.loader import SYSTEM_FILE, SystemFile, default_system, read_system

log = logging.getLogger(__name__)


def load_system(path: str | Path) -> SystemFile:
    """Read, validate and check a system file (``SystemFileError`` naming the file, key, value, allowed)."""
    system = read_system(path)
    check_system(system)
    return system


def find_system(explicit: str | Path | None = None, cwd: str | Path | None = None) -> SystemFile:
    """The system a command assesses: ``--system FILE``, else ``uav-el.toml`` in the working directory, else the
    embedded default. Anything named ``uav-el.toml`` in the working directory is the system file: one that is not a
    regular file (a FIFO, a device, a folder, a dangling link) is refused by the reader's line naming it, not passed
    over for the default (which would assess a system other than the one the applicant put there)."""
    if explicit is not None:
        system = load_system(explicit)
    else:
        here = Path(cwd or Path.cwd()) / SYSTEM_FILE
        found = os.path.lexists(here)
        system = load_system(here) if found else default_system()
        if found:
            log.info("system file found in the working directory: %s", here)
    log.info("system assessed: %s (SHA-256 %s)", system.label, system.sha256[:12] or "-")
    return system
