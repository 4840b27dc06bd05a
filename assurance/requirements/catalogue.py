"""The check registry: which campaign check judges which requirement (docs/architecture.md section 4.8).

A check is a plain function of a ``CheckContext`` returning an ``Evidence`` record, registered with
``@check("EL-Rnn", ...)``. The campaign requirement tests (``tests/requirements``) run every registered
check, each claiming its requirement; the evidence report runs those marked ``in_report``. Neither
names a requirement id: adding a campaign requirement is one registry entry
(``assurance/requirements.yaml``) and one decorated function (``assurance.requirements.campaign_checks``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from assurance.analysis.table import results_table
from assurance.campaign import readouts
from assurance.requirements.records import Evidence

ARTEFACTS: tuple[str, ...] = ("results_table", "report")
"""What a check may rely on beyond the run folder: the results table (``results.csv``), the report itself."""


class CheckContext:
    """What a check may read: the run, its manifest, readouts and results table (each loaded once, on first
    use, unless given), the registry's parameters, and a work folder for checks that write (re-runs)."""

    def __init__(self, run: str | Path, parameters: Mapping[str, Any], *, n_boot: int = 2000,
                 work_dir: str | Path | None = None, **loaded: Any) -> None:
        unknown = set(loaded) - {"manifest", "images", "candidates", "table"}
        if unknown:
            raise TypeError(f"CheckContext: unknown table(s) {sorted(unknown)}")
        self.run, self.parameters, self.n_boot = Path(run), parameters, n_boot
        self._work_dir = None if work_dir is None else Path(work_dir)
        self._loaded: dict[str, Any] = dict(loaded)

    def with_work_dir(self, work_dir: str | Path) -> CheckContext:
        """The same context (sharing what is loaded) with its own work folder."""
        other = CheckContext(self.run, self.parameters, n_boot=self.n_boot, work_dir=work_dir)
        other._loaded = self._loaded
        return other

    def _get(self, name: str, load: Callable[[], Any]) -> Any:
        if name not in self._loaded:
            self._loaded[name] = load()
        return self._loaded[name]

    @property
    def work_dir(self) -> Path:
        """Where a check may write (ValueError when the context has none)."""
        if self._work_dir is None:
            raise ValueError("this check writes files: give the CheckContext a work_dir")
        return self._work_dir

    @property
    def manifest(self) -> dict[str, Any]:
        """The run's manifest."""
        return self._get("manifest", lambda: readouts.read_manifest(self.run))

    @property
    def images(self) -> Any:
        """The run's images readouts (one row per image and configuration)."""
        return self._get("images", lambda: readouts.load_table(self.run, "images"))

    @property
    def candidates(self) -> Any:
        """The run's candidates readouts (one row per candidate and configuration)."""
        return self._get("candidates", lambda: readouts.load_table(self.run, "candidates"))

    @property
    def table(self) -> Any:
        """The run's results table (``n_boot`` bootstrap resamples)."""
        return self._get("table", lambda: results_table(self.run, n_boot=self.n_boot))

    @property
    def input_size(self) -> tuple[int, int] | None:
        """(W, H) of the run's input images (its first evaluated image); None when no image was evaluated."""
        return readouts.input_size(self.images)


@dataclass(frozen=True)
class Check:
    """One registered campaign check and what it relies on."""

    requirement: str
    name: str
    func: Callable[[CheckContext], Evidence]
    parameters: tuple[str, ...] = ()
    """The registry parameters it reads (``parameters:`` of ``assurance/requirements.yaml``)."""
    artefacts: tuple[str, ...] = ()
    """What it relies on beyond the run folder (``ARTEFACTS``); the report's matrix names them."""
    readouts: bool = True
    """It needs the run's readouts: a run without a finished shard skips it (not verified)."""
    in_report: bool = True
    """The evidence report runs it too (False: too slow, or writes files); at most one such per requirement."""

    def __call__(self, ctx: CheckContext) -> Evidence:
        """Run the check on ``ctx``; the record carries this check's requirement id."""
        return dataclasses.replace(self.func(ctx), requirement=self.requirement)


CHECKS: dict[str, Check] = {}
"""Every registered check by function name, in registration order (the report's order)."""


def check(requirement: str, *, parameters: tuple[str, ...] = (), artefacts: tuple[str, ...] = (),
          readouts: bool = True, in_report: bool = True,
          ) -> Callable[[Callable[[CheckContext], Evidence]], Callable[[CheckContext], Evidence]]:
    """Register the decorated function as a campaign check of ``requirement`` (its name must be unique)."""
    bad = [a for a in artefacts if a not in ARTEFACTS]
    if bad:
        raise ValueError(f"check of {requirement}: unknown artefact(s) {bad}; valid: {', '.join(ARTEFACTS)}")

    def wrap(func: Callable[[CheckContext], Evidence]) -> Callable[[CheckContext], Evidence]:
        if func.__name__ in CHECKS:
            raise ValueError(f"a campaign check named {func.__name__!r} is already registered")
        if in_report and any(c.in_report for c in checks_of(requirement)):
            raise ValueError(f"{requirement} already has a check the report runs (one per requirement)")
        CHECKS[func.__name__] = Check(requirement, func.__name__, func, tuple(parameters), tuple(artefacts),
                                      readouts, in_report)
        return func
    return wrap


def checks_of(requirement: str) -> list[Check]:
    """The registered checks of one requirement, in registration order."""
    return [c for c in CHECKS.values() if c.requirement == requirement]


def artefacts_of(requirement: str) -> list[str]:
    """What the checks of ``requirement`` rely on beyond the run folder, in ``ARTEFACTS`` order."""
    used = {a for c in checks_of(requirement) for a in c.artefacts}
    return [a for a in ARTEFACTS if a in used]


def requirements_reading(parameter: str) -> list[str]:
    """The requirements whose checks read the registry parameter ``parameter``, in registration order."""
    return list(dict.fromkeys(c.requirement for c in CHECKS.values() if parameter in c.parameters))
