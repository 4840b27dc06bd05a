"""The record a campaign check returns: pass, fail or insufficient, with a summary and detail rows (section 4.6).

``insufficient`` means too little data to decide: the campaign requirement tests turn it into a skip,
so the requirement is "not verified", never "failed".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

PASS, FAIL, INSUFFICIENT = "pass", "fail", "insufficient"


@dataclass(frozen=True)
class Evidence:
    """What a campaign check found: ``status`` pass / fail / insufficient, a one-line summary, details.

    ``rows`` are records (dicts of plain values) for the report's tables; ``columns`` names their keys
    in display order. ``requirement`` is the id the check registry (``catalogue``) stamps on it.
    """

    name: str
    status: str
    summary: str
    rows: tuple[dict[str, Any], ...] = ()
    columns: tuple[str, ...] = ()
    requirement: str = ""

    def __post_init__(self) -> None:
        if self.status not in (PASS, FAIL, INSUFFICIENT):
            raise ValueError(f"status must be pass, fail or insufficient, got {self.status!r}")

    def message(self, limit: int = 10) -> str:
        """The summary, with the first ``limit`` detail rows (for a test's failure message)."""
        lines = [self.summary]
        for row in self.rows[:limit]:
            lines.append("  " + ", ".join(f"{k}={row.get(k)}" for k in (self.columns or row)))
        if len(self.rows) > limit:
            lines.append(f"  ... {len(self.rows) - limit} more")
        return "\n".join(lines)
