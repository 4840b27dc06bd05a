"""Compare what the flight logs show with what the certification run measured on its clean test frames.

The run's side (:func:`certified`) is read from its readouts: the rows of the configuration the logs fly, on the
unperturbed frames (perturbation ``none``), faulted rows left out: the frame gate's scores (``frame_gate_score``),
its refusals (reason ``out_of_domain``), the candidates the walk examined with their monitor scores and verdicts,
the default actions, the deadline overruns, the decision times and the reasons. The service side is the logs'
:class:`~assurance.inservice.reader.LogSummary`.

Like is compared with like. A campaign judges every candidate of every frame with every configuration (evaluation
mode) and goes on past a refusal; flight judges only the candidates its walk reaches, and none of a frame it refused.
So the run's candidate scores and rejections are those of the candidates its walk examined on frames it did not
refuse (``out_of_domain``, ``outside_odd``), and its decision time is the one flight would have had, as EL-R13 times
it: segmentation, candidates and the walk's monitoring (``overhead_s``: the seconds of the judgements the walk made),
the later stages left out where flight stops (a refused frame: segmentation only; a frame outside the declared
domain: none). The logs' decision time is the same sum of the same stages (:data:`DECISION_STAGES`); their whole
decision time (reading the frame included) is shown apart, as the service's own.

Each comparison is a plain dict of finished numbers: a two-sample Kolmogorov-Smirnov test of the score
distributions (``scipy.stats.ks_2samp``: p-value and its statistic D, the effect size: the largest gap between the
two cumulative distributions, 0 to 1), and each rate with its two-sided exact (Clopper-Pearson) interval in service
and in the run, with Fisher's exact test of their difference.
"""

from __future__ import annotations

import json
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
from assurance.inservice.reader import DECISION_STAGES, LogSummary, reason_kind
from el.base import records, userfiles
from el.base.hashing import sha256_file

MIN_DRIFT_N = 10
"""Scores needed on each side before a two-sample test is run (fewer: undecided)."""
CLEAN = "none"
"""The perturbation of the run's clean test frames."""


class RunMismatchError(ValueError):
    """The logs fly a configuration the run did not assess: one line naming both."""


def run_identity(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """The identity a run's manifest records (network weights, system file and frame gate SHA-256), as a flight
    log's records carry it (``el.flight.flightlog``), and the gate file's own SHA-256 (:func:`gate_file_sha256`: the
    one the
    evidence report names)."""
    gate = (manifest.get("config") or {}).get("gate") or {}
    gate = gate if isinstance(gate, Mapping) else {}
    return {"network_sha256": (manifest.get("weights") or {}).get("sha256"),
            "system_sha256": (manifest.get("system") or {}).get("sha256"),
            "gate_sha256": gate.get("sha256"), "gate_file_sha256": gate_file_sha256(gate.get("path"),
                                                                                   gate.get("sha256"))}


def gate_file_sha256(path: Any, body_sha256: Any) -> str | None:
    """The SHA-256 of the gate file at ``path`` when its body is still the one the run recorded (``body_sha256``),
    as the evidence report names the gate (``assurance.evidence.facts.gate_identity``); None without a gate, or when
    the file is not readable here or its body differs."""
    if not path or not body_sha256:
        return None
    try:
        doc = json.loads(userfiles.read_text(Path(path), what="frame gate", max_bytes=userfiles.MAX_RECORD_BYTES))
        body = doc.get("body", doc) if isinstance(doc, dict) else None
        same = isinstance(body, dict) and records.body_sha256(body) == body_sha256
        return sha256_file(Path(path)) if same else None
    except (OSError, ValueError, TypeError):
        return None


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


def flight_seconds(rows: Any) -> np.ndarray:
    """Each run row's decision time as flight would have had it (see the module docstring): segmentation,
    candidates and the walk's monitoring, without the stages flight does not run past a refusal."""
    kinds = [reason_kind(str(r)) for r in rows["reason"]]

    def stage(name: str) -> np.ndarray:
        return np.nan_to_num(rows[name].to_numpy(float), nan=0.0) if name in rows else np.zeros(len(rows))

    seg, rest = stage(DECISION_STAGES[0]), sum(stage(name) for name in DECISION_STAGES[1:])
    refused = np.array([k == "out_of_domain" for k in kinds], bool)
    outside = np.array([k == "outside_odd" for k in kinds], bool)
    return np.where(outside, 0.0, np.where(refused, seg, seg + rest))


def certified(run: str | Path, monitor: str, *, budget_s: float | None = None) -> Certified:
    """The run's clean-frame measurements of ``monitor`` (see the module docstring); ``budget_s``: the deadline a
    decision time is judged against (a run's ``timeout`` reasons count as overruns too)."""
    images = readouts.load_table(run, "images")
    cands = readouts.load_table(run, "candidates")
    rows = images[(images["perturbation"] == CLEAN) & (images["monitor"] == monitor)]
    rows = rows[rows["fault"].fillna("") == ""]
    kinds = Counter(reason_kind(str(r)) for r in rows["reason"])
    times = flight_seconds(rows)
    over = np.array(rows["reason"] == "timeout", dtype=bool)  # a copy: pandas hands out read-only arrays
    if budget_s is not None:
        over = over | (times > budget_s)
    stopped = {str(k) for k, r in zip(rows["key"], rows["reason"], strict=True)
               if reason_kind(str(r)) in ("out_of_domain", "outside_odd")}
    c = cands[(cands["perturbation"] == CLEAN) & (cands["monitor"] == monitor)]
    c = c[~c["key"].astype(str).isin(stopped)]  # flight judges no candidate of a frame it refused
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


def rate(k_service: int, n_service: int, k_run: int, n_run: int, conf: float = 0.95, *,
         unlogged: int = 0) -> dict[str, Any]:
    """A rate in service and in the run, each with its two-sided exact interval at ``conf``, and the p-value of
    Fisher's exact test that they are the same (None without data on a side). ``unlogged``: decisions of the service
    whose records are missing (sequence gaps), each of which may or may not have been an event (the SPIs judge both
    ways, ``assurance.inservice.spi``)."""
    p = None
    if n_service and n_run:
        table = [[k_service, n_service - k_service], [k_run, n_run - k_run]]
        p = float(stats.fisher_exact(table).pvalue)
    return {"service": {**_side(k_service, n_service, conf), "unlogged": int(unlogged)},
            "run": _side(k_run, n_run, conf), "p_value": p, "conf": conf}


def _p95(values: Sequence[float]) -> float | None:
    return float(np.percentile(np.asarray(values, float), 95)) if len(values) else None


def _poses(summary: LogSummary, odd: Any) -> dict[str, Any]:
    declared = None if odd is None else {"height_m": list(odd.height_m), "pitch_deg": list(odd.pitch_deg)}
    return {"observed": {k: list(v) for k, v in summary.pose_range.items()}, "declared": declared,
            "outside": dict(sorted(summary.pose_outside.items())), "outside_total": sum(summary.pose_outside.values()),
            "domain_verdicts": dict(sorted(summary.domain.items()))}


def compare(summary: LogSummary, cert: Certified, *, conf: float = 0.95, odd: Any = None) -> dict[str, Any]:
    """Every comparison of the logs with the run (see the module docstring), as finished numbers."""
    n, gaps = summary.records, summary.findings.unlogged
    kinds = sorted(set(summary.reasons) | set(cert.reasons))
    return {
        "decisions": {"service": n, "run": cert.frames, "unlogged": gaps},
        "frame_gate": {"drift": drift(summary.gate_scores.values, cert.gate_scores),
                       "refusal": rate(summary.refusals, n, cert.refusals, cert.frames, conf, unlogged=gaps),
                       "thresholds": sorted(summary.gate_thresholds),
                       "file_sha256_in_logs": sorted(summary.gate_files)},
        "monitor": {"drift": drift(summary.candidate_scores.values, cert.candidate_scores),
                    "rejection": rate(summary.rejected, summary.judged, cert.rejected, cert.judged, conf)},
        "default": rate(summary.defaults, n, cert.defaults, cert.frames, conf, unlogged=gaps),
        "overrun": rate(summary.overruns, n, cert.overruns, cert.frames, conf, unlogged=gaps),
        "decision_time": {"measure": "segmentation + candidates + the walk's monitoring (as EL-R13 times a decision; "
                                     "reading the frame left out); on the run, the stages flight would have run",
                          "p95_service_s": _p95(summary.decision_times.values), "p95_run_s": _p95(cert.times),
                          "n_service": summary.decision_times.seen, "n_run": len(cert.times),
                          "p95_service_whole_s": _p95(summary.times.values)},
        "reasons": [{"reason": k, "service": summary.reasons.get(k, 0), "run": cert.reasons.get(k, 0)} for k in kinds],
        "poses": _poses(summary, odd),
    }


__all__ = ["MIN_DRIFT_N", "Certified", "RunMismatchError", "certified", "compare", "drift", "flight_seconds",
           "flown_monitor", "gate_file_sha256", "rate", "run_identity"]
