"""How a card records a file or folder: relative to the working directory when inside it, so a committed card
does not carry the layout of the machine that wrote it; absolute otherwise."""

from __future__ import annotations

from pathlib import Path


def shown_path(path: str | Path) -> str:
    """``path`` relative to the working directory if it lies inside it, else absolute (POSIX separators)."""
    p = Path(path).resolve()
    try:
        return p.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return p.as_posix()
