"""What no monitor can prevent: the unsafe landings a perfect monitor would still make.

A monitor chooses among the core model's candidates or rejects them all. A perfect one lands on a truly safe
candidate when the frame has one, and otherwise takes the default action, which is unsafe when its own area is
(``h_default >= 1``, the campaign's judgement of the default action). The frames where neither way out is safe are
the floor under every monitor's unsafe landings on that run: the rest of a monitor's unsafe landings lie within a
monitor's reach, these only within the core model's (more candidates) or the default action's. Read from a
campaign's readouts; the truth of every candidate is recorded whatever its monitor judged.

The same readouts bound the safety gain any monitor can add over the core model (``g_rm``, the paper's G_RM): a
monitor decides among the core model's candidates and the default area, so no decision of a frame has a lower true
hazard than the lowest on offer; ``perfect_g_rm`` is the mean of ``H(c~)`` minus that lowest hazard over the frames
(an oracle that knows every true hazard; a monitor that only vetoes, walking the core model's ranking, stays
below it, since the best-ranked safe candidate need not be the least hazardous).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from assurance.campaign import readouts

__all__ = ["floor_markdown", "monitor_floor"]

FRAME = ["perturbation", "severity", "key"]
COLUMNS = ["perturbation", "severity", "images", "no_candidate", "all_unsafe", "floor", "perfect_g_rm"]


def monitor_floor(images: pd.DataFrame, candidates: pd.DataFrame) -> pd.DataFrame:
    """Per perturbation and severity: the judged ``images`` (frames no configuration faulted on), those with
    ``no_candidate``, those whose candidates are ``all_unsafe``, and the ``floor``: frames with no safe candidate
    whose default area is unsafe too, the unsafe landings a perfect monitor would make; and ``perfect_g_rm``, the
    most safety gain any monitor can add over the core model (NaN where the readouts carry no true hazards)."""
    if not len(images):
        return pd.DataFrame(columns=COLUMNS)
    faulted = images["fault"].fillna("").astype(str) != ""
    top = images["h_top"] if "h_top" in images else float("nan")
    frames = images.assign(faulted=faulted, h_top=top).groupby(FRAME).agg(
        h_default=("h_default", "first"), h_top=("h_top", "first"), n=("candidates", "first"),
        faulted=("faulted", "any"))
    frames = frames[~frames["faulted"]]
    safe = (~candidates["true_unsafe"].astype(bool)).groupby([candidates[c] for c in FRAME]).any() \
        if len(candidates) else pd.Series(dtype=bool)
    any_safe = safe.reindex(frames.index, fill_value=False).astype(bool)
    n = frames["n"].fillna(0).astype(int)
    h_default = frames["h_default"].astype(float)
    frames = frames.assign(no_candidate=n == 0, all_unsafe=(n > 0) & ~any_safe, floor=~any_safe & (h_default >= 1.0),
                           gain=_perfect_gain(frames, candidates)).reset_index()
    out = frames.groupby(["perturbation", "severity"], sort=True).agg(
        images=("key", "size"), no_candidate=("no_candidate", "sum"), all_unsafe=("all_unsafe", "sum"),
        floor=("floor", "sum"), perfect_g_rm=("gain", "mean")).reset_index()
    return out[COLUMNS].astype({c: int for c in COLUMNS[2:-1]})


def _perfect_gain(frames: pd.DataFrame, candidates: pd.DataFrame) -> pd.Series:
    """Per frame, ``H(c~)`` (:func:`readouts.core_hazard`) minus the lowest true hazard among its candidates and its
    default area."""
    if "true_hazard" not in candidates:
        return pd.Series(float("nan"), index=frames.index)
    lowest = candidates.groupby(FRAME)["true_hazard"].min().reindex(frames.index).astype(float)
    return readouts.core_hazard(frames).astype(float) - np.fmin(lowest, frames["h_default"].astype(float))


def floor_markdown(floor: pd.DataFrame) -> str:
    """The floor as a Markdown table (one row per perturbation and severity)."""
    lines = ["| Perturbation | Images | No candidate | Every candidate unsafe | Unsafe landings a perfect monitor "
             "makes (the default area unsafe too; rate) | Most G_RM a monitor can add |", "|---|---|---|---|---|---|"]
    lines += [f"| {r.perturbation} (s{r.severity}) | {r.images} | {r.no_candidate} | {r.all_unsafe} | {r.floor} "
              f"({r.floor / r.images:.3f}) | {_gain(r.perfect_g_rm)} |" for r in floor.itertuples() if r.images]
    return "\n".join(lines) + "\n"


def _gain(value: float) -> str:
    return "n/a" if pd.isna(value) else f"{value:+.3f}"
