"""Paths the harness writes and reads: how a card records a file or folder (relative to the working directory when
inside it, so a committed card does not carry the layout of the machine that wrote it; absolute otherwise), and
where a calibration card a target names lies (under the package root, never the working directory)."""

from __future__ import annotations

from pathlib import Path


def shown_path(path: str | Path) -> str:
    """``path`` relative to the working directory if it lies inside it, else absolute (POSIX separators)."""
    p = Path(path).resolve()
    try:
        return p.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return p.as_posix()


PACKAGE_ROOT = Path(__file__).resolve().parents[1]
"""The folder holding ``el`` and ``assurance`` (the shipped registry names cards relative to it)."""


def card_path(value: str | Path | None) -> Path | None:
    """Where the calibration card a target names is: an absolute path as it is, a relative one under the package
    root (the shipped registry names ``el/monitors/data/calibration.json``), never the working directory."""
    if value is None or str(value).strip() == "":
        return None
    p = Path(value)
    return p if p.is_absolute() else PACKAGE_ROOT / p
