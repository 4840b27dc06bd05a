"""Compare what the flight logs show with what the certification run measured on its clean test frames.

The run's side (:func:`certified`) is read from its readouts: the rows of the configuration the logs fly, on the
unperturbed frames (perturbation ``none``), faulted rows left out: the frame gate's scores (``frame_gate_score``),
its refusals (reason ``out_of_domain``), the candidates the walk examined with their monitor scores and verdicts,
the default actions, the deadline overruns, the decision times and the reasons. The service side is the logs'
:class:`~assurance.inservice.reader.LogSummary`.

Each comparison is a plain dict of finished numbers: a two-sample Kolmogorov-Smirnov test of the score
distributions (``scipy.stats.ks_2samp``: p-value and its statistic D, the effect size: the largest gap between the
two cumulative distributions, 0 to 1), and each rate with its two-sided exact (Clopper-Pearson) interval in service
and in the run, with Fisher's exact test of their difference.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from assurance.analysis.intervals import clopper_pearson_interval
from assurance.campaign import readouts
from assurance.inservice.reader import LogSummary, reason_kind

MIN_DRIFT_N = 10
"""Scores needed on each side before a two-sample test is run (fewer: undecided)."""
CLEAN = "none"
"""The perturbation of the run's clean test frames."""


class RunMismatchError(ValueError):
    """The logs fly a configuration the run did not assess: one line naming both."""


def run_identity(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """The identity a run's manifest records (network weights, system file and frame gate SHA-256), as a flight
    log's records carry it (``el.flightlog``)."""
    gate = (manifest.get("config") or {}).get("gate") or {}
    return {"network_sha256": (manifest.get("weights") or {}).get("sha256"),
            "system_sha256": (manifest.get("system") or {}).get("sha256"),
            "gate_sha256": gate.get("sha256") if isinstance(gate, Mapping) else None}


@dataclass
class Certified:
    """What the certification run measured on its clean test frames for one monitor configuration."""

    monitor: str
    frames: int
    gate_scores: np.ndarray
    refusals: int
    candidate_scores: np.ndarray
    judged: int
    rejected: int
    defaults: int
    overruns: int
    times: np.ndarray
    reasons: Counter[str] = field(default_factory=Counter)


def flown_monitor(summary: LogSummary, manifest: Mapping[str, Any], run: str | Path) -> str:
    """The one monitor configuration the logs fly, which the run must have assessed (RunMismatchError otherwise)."""
    flown = sorted(summary.monitors)
    assessed = list((manifest.get("config") or {}).get("monitors") or [])
    if len(flown) != 1:
        raise RunMismatchError(f"the logs fly {len(flown)} monitor configurations ({', '.join(flown) or 'none'}); "
                               "compare the logs of one configuration at a time")
    if flown[0] not in assessed:
        raise RunMismatchError(f"{run}: the logs fly the monitor {flown[0]!r}, which the run did not assess "
                               f"(it assessed {', '.join(assessed)})")
    return flown[0]


def certified(run: str | Path, monitor: str, *, budget_s: float | None = None) -> Certified:
    """The run's clean-frame measurements of ``monitor`` (see the module docstring); ``budget_s``: the deadline a
    decision time is judged against (a run's ``timeout`` reasons count as overruns too)."""
    images = readouts.load_table(run, "images")
    cands = readouts.load_table(run, "candidates")
    rows = images[(images["perturbation"] == CLEAN) & (images["monitor"] == monitor)]
    rows = rows[rows["fault"].fillna("") == ""]
    kinds = Counter(reason_kind(str(r)) for r in rows["reason"])
    times = rows["total_s"].to_numpy(float)
    over = (rows["reason"] == "timeout").to_numpy(bool)
    if budget_s is not None:
        over |= np.nan_to_num(times, nan=0.0) > budget_s
    c = cands[(cands["perturbation"] == CLEAN) & (cands["monitor"] == monitor)]
    if "examined" in c:
        c = c[c["examined"].astype(bool)]
    scores = c["score"].to_numpy(float) if "score" in c else np.zeros(0)
    gate = rows["frame_gate_score"].to_numpy(float) if "frame_gate_score" in rows else np.zeros(0)
    return Certified(monitor=monitor, frames=len(rows), gate_scores=gate[np.isfinite(gate)],
                     refusals=kinds["out_of_domain"], candidate_scores=scores[np.isfinite(scores)], judged=len(c),
                     rejected=int((~c["accepted"].astype(bool)).sum()),
                     defaults=int((rows["action"] == "default").sum()),
                     overruns=int(over.sum()), times=times[np.isfinite(times)], reasons=kinds)


def drift(service: Sequence[float], run: Sequence[float]) -> dict[str, Any]:
    """The two-sample Kolmogorov-Smirnov test of service scores against the run's: D (the effect size), p-value,
    sizes and medians; ``p_value`` None when either side has fewer than :data:`MIN_DRIFT_N` scores."""
    s, r = np.asarray(service, float), np.asarray(run, float)
    out: dict[str, Any] = {"test": "two-sample Kolmogorov-Smirnov (scipy.stats.ks_2samp)", "n_service": len(s),
                           "n_run": len(r), "statistic": None, "p_value": None,
                           "median_service": float(np.median(s)) if len(s) else None,
                           "median_run": float(np.median(r)) if len(r) else None}
    if len(s) < MIN_DRIFT_N or len(r) < MIN_DRIFT_N:
        out["why_not"] = f"fewer than {MIN_DRIFT_N} scores on a side"
        return out
    res = stats.ks_2samp(s, r)
    out.update(statistic=float(res.statistic), p_value=float(res.pvalue))
    return out


def _side(k: int, n: int, conf: float) -> dict[str, Any]:
    lo, hi = clopper_pearson_interval(int(k), int(n), conf)
    return {"k": int(k), "n": int(n), "rate": (k / n) if n else None,
            "ci": [None if math.isnan(lo) else lo, None if math.isnan(hi) else hi]}


def rate(k_service: int, n_service: int, k_run: int, n_run: int, conf: float = 0.95) -> dict[str, Any]:
    """A rate in service and in the run, each with its two-sided exact interval at ``conf``, and the p-value of
    Fisher's exact test that they are the same (None without data on a side)."""
    p = None
    if n_service and n_run:
        table = [[k_service, n_service - k_service], [k_run, n_run - k_run]]
        p = float(stats.fisher_exact(table).pvalue)
    return {"service": _side(k_service, n_service, conf), "run": _side(k_run, n_run, conf), "p_value": p,
            "conf": conf}


def _p95(values: Sequence[float]) -> float | None:
    return float(np.percentile(np.asarray(values, float), 95)) if len(values) else None


def _poses(summary: LogSummary, odd: Any) -> dict[str, Any]:
    declared = None if odd is None else {"height_m": list(odd.height_m), "pitch_deg": list(odd.pitch_deg)}
    return {"observed": {k: list(v) for k, v in summary.pose_range.items()}, "declared": declared,
            "outside": dict(sorted(summary.pose_outside.items())), "outside_total": sum(summary.pose_outside.values()),
            "domain_verdicts": dict(sorted(summary.domain.items()))}


def compare(summary: LogSummary, cert: Certified, *, conf: float = 0.95, odd: Any = None) -> dict[str, Any]:
    """Every comparison of the logs with the run (see the module docstring), as finished numbers."""
    n = summary.records
    kinds = sorted(set(summary.reasons) | set(cert.reasons))
    return {
        "decisions": {"service": n, "run": cert.frames},
        "frame_gate": {"drift": drift(summary.gate_scores.values, cert.gate_scores),
                       "refusal": rate(summary.refusals, n, cert.refusals, cert.frames, conf),
                       "thresholds": sorted(summary.gate_thresholds)},
        "monitor": {"drift": drift(summary.candidate_scores.values, cert.candidate_scores),
                    "rejection": rate(summary.rejected, summary.judged, cert.rejected, cert.judged, conf)},
        "default": rate(summary.defaults, n, cert.defaults, cert.frames, conf),
        "overrun": rate(summary.overruns, n, cert.overruns, cert.frames, conf),
        "decision_time": {"p95_service_s": _p95(summary.times.values), "p95_run_s": _p95(cert.times),
                          "n_service": summary.times.seen, "n_run": len(cert.times)},
        "reasons": [{"reason": k, "service": summary.reasons.get(k, 0), "run": cert.reasons.get(k, 0)} for k in kinds],
        "poses": _poses(summary, odd),
    }


__all__ = ["MIN_DRIFT_N", "Certified", "RunMismatchError", "certified", "compare", "drift", "flown_monitor", "rate",
           "run_identity"]
