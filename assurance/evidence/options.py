"""What the auditor asks of one evidence report besides the run and the output folder (``uav-el evidence``'s options,
as data): ``assurance.evidence.report.generate`` and ``assurance.evidence.context.read_inputs`` take it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from assurance import requirements as rq


@dataclass(frozen=True, kw_only=True)
class ReportOptions:
    """What the auditor asks of one evidence report besides the run and the output folder
    (``assurance.evidence.report.generate`` says what each means; ``uav-el evidence --help`` gives the options)."""

    requirements: str | Path | None = None
    baseline: str | Path | None = None
    baseline_requirements: str | Path | None = None
    registry: str | Path | rq.Registry | None = None
    targets: Mapping[str, Any] | None = None
    targets_source: str | None = None
    strict: bool = False
    waivers: str | Path | None = None
    pdf: bool = True
    n_boot: int = 2000
    templates: str | Path | None = None
    system: Any = None
    trusted: Mapping[str, Any] | None = None
    accepted_deviations: tuple[str, ...] = ()
    benchmark: str | Path | None = None
    system_templates: bool = False
    template_seconds: float | None = None
    in_service: str | Path | None = None
