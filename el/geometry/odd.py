"""The declared operating domain (ODD): where the system's evidence reaches, checked on every frame.

A frame whose pose (the telemetry given to ``decide``) or size lies outside the declaration ends in the
default action with reason ``outside_odd: <dimension> ...``: a decision (there is no evidence of safety
there), not a fault. The in-domain perturbations and their maximum severities are part of the declaration
(what the campaigns evaluated); the flight code cannot see them on a frame, so it does not check them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from el.geometry.camera import Pose

Range = tuple[float, float]


def _range(name: str, value: Any) -> Range:
    """A closed interval [low, high] of finite numbers with low <= high."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"odd {name} must be a pair [low, high] of numbers, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"odd {name} must be [low, high] with finite low <= high, got {value!r}")
    return lo, hi


@dataclass(frozen=True, kw_only=True)
class OperatingDomain:
    """Height (m) and pitch (degrees below the horizon) ranges, image width, height (px) and aspect
    (width / height) ranges, and the in-domain perturbations with their maximum severity."""

    height_m: Range
    pitch_deg: Range
    image_width: Range
    image_height: Range
    aspect: Range
    perturbations: Mapping[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("height_m", "pitch_deg", "image_width", "image_height", "aspect"):
            object.__setattr__(self, name, _range(name, getattr(self, name)))
        sev = {}
        for name, level in dict(self.perturbations).items():
            if isinstance(level, bool) or not isinstance(level, int) or not 0 <= level <= 5:
                raise ValueError(f"odd perturbation {name!r}: the maximum severity must be an integer in 0..5, "
                                 f"got {level!r}")
            sev[str(name)] = int(level)
        object.__setattr__(self, "perturbations", dict(sorted(sev.items())))

    def outside(self, pose: Pose, size: tuple[int, int]) -> str | None:
        """The reason a frame of ``size`` (width, height) taken at ``pose`` is outside the domain, else None.

        The first dimension outside is named: ``outside_odd: height 120 m not in [40, 60] m``."""
        width, height = size
        checks = (("height", pose.height_m, self.height_m, " m"), ("pitch", pose.pitch_deg, self.pitch_deg, " deg"),
                  ("image_width", width, self.image_width, " px"), ("image_height", height, self.image_height, " px"),
                  ("aspect", width / height if height else math.inf, self.aspect, ""))
        for name, value, (lo, hi), unit in checks:
            if not lo <= value <= hi:
                return f"outside_odd: {name} {value:.4g}{unit} not in [{lo:g}, {hi:g}]{unit}"
        return None

    def covers(self, perturbation: str, severity: int) -> bool:
        """Whether a perturbation at a severity is inside the declared domain ('none' always is)."""
        return perturbation == "none" or severity <= self.perturbations.get(perturbation, -1)

    def to_dict(self) -> dict[str, Any]:
        return {"height_m": list(self.height_m), "pitch_deg": list(self.pitch_deg),
                "image_width": list(self.image_width), "image_height": list(self.image_height),
                "aspect": list(self.aspect), "perturbations": dict(self.perturbations)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> OperatingDomain:
        """The domain from its JSON record (``to_dict``); ValueError naming a missing or unknown key."""
        keys = {"height_m", "pitch_deg", "image_width", "image_height", "aspect", "perturbations"}
        unknown, missing = set(d) - keys, keys - {"perturbations"} - set(d)
        if unknown or missing:
            raise ValueError(f"odd: unknown key(s) {sorted(unknown)}, missing key(s) {sorted(missing)}")
        return cls(**{k: d[k] for k in d})


OUTSIDE_ODD = "outside_odd"
"""The prefix of the reason of a frame refused because it is outside the declared domain."""

__all__ = ["OUTSIDE_ODD", "OperatingDomain"]
