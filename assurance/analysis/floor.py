"""What no monitor can prevent: the unsafe landings a perfect monitor would still make.

A monitor chooses among the core model's candidates or rejects them all. A perfect one lands on a truly safe
candidate when the frame has one, and otherwise takes the default action, which is unsafe when its own area is
(``h_default >= 1``, the campaign's judgement of the default action). The frames where neither way out is safe are
the floor under every monitor's unsafe landings on that run: the rest of a monitor's unsafe landings lie within a
monitor's reach, these only within the core model's (more candidates) or the default action's. Read from a
campaign's readouts; the truth of every candidate is recorded whatever its monitor judged.
"""

from __future__ import annotations

import pandas as pd

__all__ = ["floor_markdown", "monitor_floor"]

FRAME = ["perturbation", "severity", "key"]
COLUMNS = ["perturbation", "severity", "images", "no_candidate", "all_unsafe", "floor"]


def monitor_floor(images: pd.DataFrame, candidates: pd.DataFrame) -> pd.DataFrame:
    """Per perturbation and severity: the judged ``images`` (frames no configuration faulted on), those with
    ``no_candidate``, those whose candidates are ``all_unsafe``, and the ``floor``: frames with no safe candidate
    whose default area is unsafe too, the unsafe landings a perfect monitor would make."""
    if not len(images):
        return pd.DataFrame(columns=COLUMNS)
    faulted = images["fault"].fillna("").astype(str) != ""
    frames = images.assign(faulted=faulted).groupby(FRAME).agg(
        h_default=("h_default", "first"), n=("candidates", "first"), faulted=("faulted", "any"))
    frames = frames[~frames["faulted"]]
    safe = (~candidates["true_unsafe"].astype(bool)).groupby([candidates[c] for c in FRAME]).any() \
        if len(candidates) else pd.Series(dtype=bool)
    any_safe = safe.reindex(frames.index, fill_value=False).astype(bool)
    n = frames["n"].fillna(0).astype(int)
    frames = frames.assign(no_candidate=n == 0, all_unsafe=(n > 0) & ~any_safe,
                           floor=~any_safe & (frames["h_default"].astype(float) >= 1.0)).reset_index()
    out = frames.groupby(["perturbation", "severity"], sort=True).agg(
        images=("key", "size"), no_candidate=("no_candidate", "sum"), all_unsafe=("all_unsafe", "sum"),
        floor=("floor", "sum")).reset_index()
    return out[COLUMNS].astype({c: int for c in COLUMNS[2:]})


def floor_markdown(floor: pd.DataFrame) -> str:
    """The floor as a Markdown table (one row per perturbation and severity)."""
    lines = ["| Perturbation | Images | No candidate | Every candidate unsafe | Unsafe landings a perfect monitor "
             "makes (the default area unsafe too; rate) |", "|---|---|---|---|---|"]
    lines += [f"| {r.perturbation} (s{r.severity}) | {r.images} | {r.no_candidate} | {r.all_unsafe} | {r.floor} "
              f"({r.floor / r.images:.3f}) |" for r in floor.itertuples() if r.images]
    return "\n".join(lines) + "\n"
