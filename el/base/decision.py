"""The landing decision as typed records that serialise to the JSON of docs/architecture.md section 5.3.

Field names are fixed (the report, the campaign and users' tools read them); coordinates and
radii are in pixels of the full-resolution input image.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from importlib import resources
from typing import Any, Literal

Action = Literal["land", "default"]

DEFAULT_AREA_BASES = {
    "nadir": "the ground below the UAV: its nadir point is in view, where the parachute brings it down",
    "nearest_ground": "the nearest ground in view (bottom centre): the nadir point is out of view (oblique camera)",
}
"""Why the default area sits where it does (``Disc.basis`` of a decision's ``default_area``), in one line each."""


@dataclass(frozen=True)
class MonitorVerdict:
    """What a runtime monitor said about one candidate, and how long it took.

    ``score``: the monitor's real-valued score (higher = more likely unsafe); ``threshold``: the
    candidate is rejected iff ``score > threshold`` (NaN for a verdict recorded without them).
    """

    name: str
    accepted: bool
    reason: str
    seconds: float
    score: float = math.nan
    threshold: float = math.nan


@dataclass(frozen=True)
class Disc:
    """A landing disc in full-resolution pixels. ``basis``: for a default area, which ground it stands for
    (a key of DEFAULT_AREA_BASES); None for a candidate's disc and for areas recorded before it."""

    x: float
    y: float
    radius_px: float
    basis: str | None = None

    @property
    def basis_text(self) -> str:
        """The one-line statement of ``basis`` (empty when there is none)."""
        return DEFAULT_AREA_BASES.get(self.basis or "", "")


@dataclass(frozen=True)
class Candidate:
    """A ranked landing candidate (rank 0 = least hazardous)."""

    rank: int
    x: float
    y: float
    radius_px: float
    hazard: float
    hazard_semantic: float
    hazard_distance: float
    monitor: MonitorVerdict | None = None

    @property
    def disc(self) -> Disc:
        return Disc(self.x, self.y, self.radius_px)


@dataclass(frozen=True)
class Decision:
    """The outcome of one emergency-landing decision.

    ``action`` is "land" (on ``candidates[selected]``) or "default" (open the parachute where
    the UAV is); ``reason`` is "accepted", "all_rejected", "no_candidate", "timeout" or
    "fault: <what failed>".
    """

    action: Action
    reason: str
    selected: int | None
    candidates: list[Candidate]
    default_area: Disc
    timings: dict[str, float] = field(default_factory=dict)
    input: dict[str, Any] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.action not in ("land", "default"):
            raise ValueError(f"action must be 'land' or 'default', got {self.action!r}")
        if (self.action == "land") != (self.selected is not None):
            raise ValueError("a 'land' decision needs a selected candidate and a 'default' one none")

    @property
    def landing_disc(self) -> Disc:
        """Where the UAV comes down: the selected candidate, or the default area."""
        if self.selected is None:
            return self.default_area
        return self.candidates[self.selected].disc

    def to_dict(self) -> dict[str, Any]:
        return _finite(asdict(self))

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, sort_keys=False)


def _finite(obj: Any) -> Any:
    """JSON has no NaN/inf: replace them by None so every output parses everywhere."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


def decision_schema() -> dict[str, Any]:
    """The JSON Schema of a decision (``el/data/decision.schema.json``)."""
    text = resources.files("el").joinpath("data/decision.schema.json").read_text(encoding="utf-8")
    return json.loads(text)
