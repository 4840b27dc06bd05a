"""The harness's own exceptions, on the project's one root (``el.errors.UavElError``)."""

from __future__ import annotations

from el.errors import UavElError


class CommandError(UavElError):
    """An expected failure of a command: printed as one line, exit code 2."""


__all__ = ["CommandError", "UavElError"]
