"""Find and load the system a command assesses: ``--system FILE``, else ``uav-el.toml`` here, else the default."""

from __future__ import annotations

from pathlib import Path

from assurance.system.checks import check_system
from assurance.system.loader import SYSTEM_FILE, SystemFile, default_system, read_system


def load_system(path: str | Path) -> SystemFile:
    """Read, validate and check a system file (``SystemFileError`` naming the file, key, value, allowed)."""
    system = read_system(path)
    check_system(system)
    return system


def find_system(explicit: str | Path | None = None, cwd: str | Path | None = None) -> SystemFile:
    """The system a command assesses: ``--system FILE``, else ``uav-el.toml`` in the working directory, else the
    embedded default."""
    if explicit is not None:
        return load_system(explicit)
    here = Path(cwd or Path.cwd()) / SYSTEM_FILE
    return load_system(here) if here.is_file() else default_system()
