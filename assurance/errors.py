"""The harness's own exceptions, on the project's one root (``el.base.errors.UavElError``).

The command line catches these without importing any command (``RunError``/``DamagedRunError`` are re-exported by
``assurance.campaign.readouts``). The harness's other expected failures derive from the same root where they are
defined: ``requirements.RegistryError``, ``headline.HeadlineError``, ``sweep.SweepError`` (each also a
``ValueError``)."""

from __future__ import annotations

from pathlib import Path

from el.base.errors import UavElError


class CommandError(UavElError):
    """An expected failure of a command: printed as one line, exit code 2."""


class RunError(UavElError, ValueError):
    """A run folder is missing, not a run, or belongs to another campaign."""


class DamagedRunError(RunError):
    """A run's readouts fail verification (a shard altered, truncated or missing): ``problems`` names them."""

    def __init__(self, run_dir: str | Path, problems: list[str], *, headline: str | None = None,
                 shown: int = 5) -> None:
        """``headline``: what the run is instead of the damaged-run line (then no re-run advice); the message
        lists the first ``shown`` problems."""
        self.run_dir, self.problems = Path(run_dir), list(problems)
        first = "; ".join(problems[:shown]) + (f"; ... {len(problems) - shown} more" if len(problems) > shown else "")
        if headline is not None:
            super().__init__(f"{run_dir}: {headline}: {first}")
            return
        super().__init__(f"{run_dir}: damaged run, {len(problems)} shard problem(s): {first} "
                         "(re-run the same `uav-el campaign` command to re-compute the damaged shards)")


__all__ = ["CommandError", "DamagedRunError", "RunError", "UavElError"]
