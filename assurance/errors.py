"""The harness's own exceptions, on the project's one root (``el.errors.UavElError``).

The harness's other expected failures derive from the same root where they are defined:
``readouts.RunError`` / ``DamagedRunError``, ``requirements.RegistryError``, ``headline.HeadlineError``,
``sweep.SweepError`` (each also a ``ValueError``)."""

from __future__ import annotations

from el.errors import UavElError


class CommandError(UavElError):
    """An expected failure of a command: printed as one line, exit code 2."""


__all__ = ["CommandError", "UavElError"]
