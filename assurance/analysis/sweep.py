"""Threshold sweeps replayed from a campaign's readouts: what each threshold of a monitor would decide.

A monitor rejects a candidate iff its score > threshold, and the decision loop lands on the first
accepted candidate in hazard order, else takes the default action (docs/architecture.md section 3.7).
A campaign judges every candidate and records its score and true hazard, so the decision at any other
threshold is replayed exactly without running the network again. This is how the deployed threshold
is chosen on the validation split (`uav-el sweep --choose`); the test split only confirms it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from assurance.campaign.readouts import core_hazard
from el.base.errors import UavElError
from el.monitors.spec import walk_of
from el.monitors.walk import HAZARD, check_walk

IMAGE_KEYS = ["perturbation", "severity", "key"]


class SweepError(UavElError, ValueError):
    """A run that cannot be swept for this monitor (no scores, no such configuration)."""


def monitor_rows(images: pd.DataFrame, candidates: pd.DataFrame, monitor: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The image and candidate readouts of one configuration, checked to carry scores."""
    if monitor not in set(images["monitor"]):
        have = ", ".join(sorted(set(images["monitor"])))
        raise SweepError(f"no configuration {monitor!r} in the run (it has: {have})")
    im = images[images["monitor"] == monitor].copy()
    ca = candidates[candidates["monitor"] == monitor].copy()
    if "score" not in ca.columns or (len(ca) and ca["score"].isna().all()):
        raise SweepError(f"the readouts of {monitor!r} hold no candidate scores (a run made before scores were "
                         "recorded): re-run the campaign")
    return im, ca


def replay(images: pd.DataFrame, candidates: pd.DataFrame, threshold: float, walk: str = HAZARD) -> pd.DataFrame:
    """Per image: the true hazard of the decision at ``threshold`` (one configuration's readouts) when
    the decision loop walks the candidates by ``walk`` (``el.monitors.walk``).

    An image with a fault keeps the default action, as the decision loop does.
    """
    acc = candidates[candidates["score"] <= threshold]
    order = ["rank"] if check_walk(walk) == HAZARD else ["score", "rank"]
    first = acc.sort_values(order, kind="mergesort").drop_duplicates(IMAGE_KEYS)[[*IMAGE_KEYS, "true_hazard"]]
    out = images[[*IMAGE_KEYS, "h_default", "h_top", "fault"]].merge(first, on=IMAGE_KEYS, how="left")
    faulty = out["fault"].fillna("").astype(str) != ""
    landed = out["true_hazard"].notna() & ~faulty
    out["h_decision"] = np.where(landed, out["true_hazard"], out["h_default"])
    out["action"] = np.where(landed, "land", "default")
    return out.drop(columns=["true_hazard"])


def default_thresholds(scores: np.ndarray, points: int = 200) -> np.ndarray:
    """Thresholds that cover every distinct verdict pattern (all unique scores, or ``points`` quantiles)."""
    s = np.unique(scores[np.isfinite(scores)])
    if s.size == 0:
        return np.array([0.0])
    if s.size > points:
        s = np.unique(np.quantile(s, np.linspace(0.0, 1.0, points)))
    below = s[0] - max(1e-9, abs(s[0]) * 1e-9)  # rejects every candidate
    return np.concatenate([[below], s])


def sweep(images: pd.DataFrame, candidates: pd.DataFrame, monitor: str,
          thresholds: Sequence[float] | None = None, walks: Sequence[str] | None = None) -> pd.DataFrame:
    """One row per (walk, threshold, perturbation): unsafe landings, G*, default share, miss and FP rates.

    ``walks``: the walk orders to replay (default: the configuration's own)."""
    im, ca = monitor_rows(images, candidates, monitor)
    own = walk_of(monitor)
    run_t = float(ca["threshold"].iloc[0]) if len(ca) and "threshold" in ca.columns else float("nan")
    ts = np.asarray(thresholds if thresholds is not None else default_thresholds(ca["score"].to_numpy(float)))
    if np.isfinite(run_t):  # the run's own threshold is always one of the rows
        ts = np.unique(np.append(ts, run_t))
    unsafe = ca["true_unsafe"].astype(bool).to_numpy()
    rows = []
    for walk, t in ((w, t) for w in (walks or [own]) for t in ts):
        dec = replay(im, ca, float(t), walk)
        rej = ca["score"].to_numpy(float) > t
        for pert, g in dec.groupby("perturbation", sort=True):
            in_p = (ca["perturbation"] == pert).to_numpy()
            u, s = unsafe & in_p, ~unsafe & in_p
            rows.append({
                "monitor": monitor, "walk": walk, "run_walk": own, "threshold": float(t),
                "run_threshold": run_t, "perturbation": pert,
                "images": len(g),
                "unsafe_landings": int((g["h_decision"] >= 1.0).sum()),
                "unsafe_landing_rate": float((g["h_decision"] >= 1.0).mean()),
                "g_star": float((g["h_default"] - g["h_decision"]).mean()),
                "g_rm": float((core_hazard(g) - g["h_decision"]).mean()),
                "default_rate": float((g["action"] == "default").mean()),
                "miss_rate": float((~rej & u).sum() / u.sum()) if u.any() else float("nan"),
                "fp_rate": float((rej & s).sum() / s.sum()) if s.any() else float("nan"),
            })
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Choice:
    """The threshold a sweep picks and what it gives over all perturbations of the run."""

    monitor: str
    walk: str
    threshold: float
    unsafe_landings: int
    images: int
    g_star: float
    miss_rate: float
    fp_rate: float


def totals(table: pd.DataFrame) -> pd.DataFrame:
    """Per threshold, summed over perturbations: unsafe landings, images, mean G*, mean miss/FP rate."""
    g = table.groupby(["monitor", "walk", "threshold"], sort=True)
    return pd.DataFrame({
        "unsafe_landings": g["unsafe_landings"].sum(), "images": g["images"].sum(),
        "g_star": g.apply(lambda d: float(np.average(d["g_star"], weights=d["images"])), include_groups=False),
        "miss_rate": g["miss_rate"].mean(), "fp_rate": g["fp_rate"].mean(),
    }).reset_index()


def choose(table: pd.DataFrame) -> Choice:
    """The threshold with the fewest unsafe landings over all perturbations; ties: the larger G*, then
    the lower miss rate (the more cautious of equally safe thresholds)."""
    t = totals(table).sort_values(["unsafe_landings", "g_star", "miss_rate"], ascending=[True, False, True],
                                  kind="mergesort")
    best = t.iloc[0]
    return Choice(str(best["monitor"]), str(best["walk"]), float(best["threshold"]),
                  int(best["unsafe_landings"]), int(best["images"]),
                  float(best["g_star"]), float(best["miss_rate"]), float(best["fp_rate"]))
