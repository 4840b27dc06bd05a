"""Calibration of a monitor's threshold with a finite-sample, distribution-free guarantee.

The monitor rejects a candidate iff its score is above the threshold ``t``, so it accepts an unsafe
candidate iff its score is ``<= t``. From the scores ``s_(1) <= ... <= s_(n)`` of the ``n`` truly
unsafe calibration candidates, :func:`calibrate_threshold` takes the largest ``k`` with

    P(Binomial(n, miss_rate) <= k - 1) <= 1 - confidence

and sets ``t`` just below ``s_(k)`` (the largest float < ``s_(k)``), so the monitor accepts exactly the
unsafe calibration candidates scoring below ``s_(k)`` (at most ``k - 1``). For a new unsafe candidate
drawn from the same distribution as the calibration ones (exchangeable; any distribution, ties
included), with probability at least ``confidence`` over the calibration sample,

    P(accept an unsafe candidate) <= miss_rate.

This is the order-statistic tolerance bound (Wilks 1941; see also Vovk's and Angelopoulos & Bates'
"conformal risk control", and the PAC / "training-conditional" conformal guarantee of Vovk 2012). The
condition is the same as the one-sided Clopper-Pearson upper bound of ``k - 1`` misses in ``n`` being
``<= miss_rate`` (Clopper & Pearson, Biometrika 1934), which the card records as ``bound``. Proof
sketch: let ``q`` be the largest x with ``P(S < x) <= miss_rate``; if ``P(S < s_(k)) > miss_rate``
then ``s_(k) > q``, so at most ``k - 1`` of the ``n`` scores are ``<= q``, an event of probability
``P(Binomial(n, p) <= k - 1)`` with ``p = P(S <= q) >= miss_rate``, at most the chosen ``1 - confidence``.

With too few unsafe candidates (``(1 - miss_rate)^n > 1 - confidence``, e.g. n < 59 for 0.05 / 0.95) no
threshold can be certified: :class:`CalibrationError`.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from assurance.analysis.criteria import candidate_threshold
from assurance.analysis.guarantee import _check_rates, calibrate_threshold, min_unsafe_needed
from assurance.campaign.run import CampaignConfig, Task, plan, run_task
from assurance.fitting.network_identity import network_record
from assurance.paths import shown_path
from assurance.progress import progress as bar
from assurance.system.model import load_model_spec
from el.base.hashing import sha256_file
from el.geometry.config import CoreConfig
from el.monitors import build_monitor
from el.monitors.calibration import CalibrationError, card_document
from el.monitors.spec import THRESHOLD, parse_monitor_spec
from el.segmentation.contract import labels_of

__all__ = ["CalibrationError", "CalibrationScenes", "ThresholdRule", "calibrate_threshold", "calibration_body",
           "min_unsafe_needed"]


@dataclass(frozen=True, kw_only=True)
class ThresholdRule:
    """How a card's threshold is chosen: by ``criterion`` (``guarantee``: an unsafe candidate accepted with
    probability at most ``miss_rate``, with ``confidence`` over the calibration sample; a benchmark criterion of
    ``assurance.analysis.criteria`` gives no guarantee, ``tnr-at-recall`` keeping ``recall`` of the unsafe ones).
    :func:`calibrate_on_data` checks the rates."""

    miss_rate: float
    confidence: float
    criterion: str = "guarantee"
    recall: float = 0.95


@dataclass(frozen=True, kw_only=True)
class CalibrationScenes:
    """The scenes a monitor is calibrated on: the first ``images`` of the folder (None: all), the core model's
    configuration (``core``; None: ``CoreConfig()``), and ``perturbations`` ((name, severity): a system's declared
    ones, ``assurance.campaign.perturbation_plan.fit_levels``; None: clean only)."""

    images: int | None = None
    core: Any = None
    perturbations: Sequence[tuple[str, int]] | None = None


def calibration_body(scores: Any, unsafe: Any, *, monitor: str, rule: ThresholdRule, split: dict[str, Any],
                     weights: dict[str, Any], monitor_model: str | None = None) -> dict[str, Any]:
    """The card body: the calibrated threshold from the candidates' scores and truths, with what it rests on
    (``monitor_model``: the SHA-256 of the monitor's fitted model file, if it has one) and the rule that chose it
    (:class:`ThresholdRule`; a criterion other than ``guarantee`` gives no guarantee: see :func:`criterion_body`)."""
    miss_rate, confidence, criterion, recall = rule.miss_rate, rule.confidence, rule.criterion, rule.recall
    base = parse_monitor_spec(monitor)
    if base is None:
        raise CalibrationError("'none' has no threshold to calibrate")
    base = base.base
    s = np.asarray(scores, dtype=np.float64)
    y = np.asarray(unsafe, dtype=bool)
    if criterion != "guarantee":
        return criterion_body(s, y, base.name, criterion, recall, split=split, weights=weights,
                              monitor_model=monitor_model)
    res = calibrate_threshold(s[y], miss_rate, confidence)
    sep = "," if ":" in base.name else ":"
    spec = parse_monitor_spec(f"{base.name}{sep}{THRESHOLD}={res['threshold']!r}")
    safe = s[~y]
    return {
        "monitor": base.name, "spec": spec.name, "threshold": res["threshold"],
        "miss_rate": float(miss_rate), "confidence": float(confidence), "bound": res["bound"],
        "order_statistic_k": res["k"],
        "counts": {"candidates": int(s.size), "unsafe": res["n"], "safe": int(safe.size),
                   "unsafe_accepted": res["accepted"],
                   "safe_rejected": int((safe > res["threshold"]).sum())},
        "safe_rejected_rate": float((safe > res["threshold"]).mean()) if safe.size else None,
        "guarantee": (f"with confidence {confidence:g} over the calibration sample, a truly unsafe candidate "
                      f"from the calibration distribution is accepted with probability at most {miss_rate:g} "
                      f"(Clopper-Pearson bound of this sample: {res['bound']:.4f})"),
        "method": ("order statistic + binomial tail (Wilks 1941; Clopper-Pearson 1934); "
                   "assurance/fitting/calibration.py"),
        "split": split, "weights": weights, "monitor_model": {"sha256": monitor_model},
        "criterion": {"name": "guarantee", "recall": None},
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }


def criterion_body(s: np.ndarray, y: np.ndarray, monitor: str, criterion: str, recall: float, *,
                   split: dict[str, Any], weights: dict[str, Any], monitor_model: str | None) -> dict[str, Any]:
    """A card whose threshold a benchmark criterion chose (``f1``, ``g-mean``, ``tnr-at-recall``): the same fields,
    with ``miss_rate``, ``confidence``, ``bound`` and ``order_statistic_k`` None (no guarantee) and the criterion."""
    try:
        threshold, note = candidate_threshold(criterion, s, y, recall=recall)
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    sep = "," if ":" in monitor else ":"
    spec = parse_monitor_spec(f"{monitor}{sep}{THRESHOLD}={threshold!r}")
    safe, bad = s[~y], s[y]
    return {
        "monitor": monitor, "spec": spec.name, "threshold": threshold,
        "miss_rate": None, "confidence": None, "bound": None, "order_statistic_k": None,
        "counts": {"candidates": int(s.size), "unsafe": int(bad.size), "safe": int(safe.size),
                   "unsafe_accepted": int((bad <= threshold).sum()), "safe_rejected": int((safe > threshold).sum())},
        "safe_rejected_rate": float((safe > threshold).mean()) if safe.size else None,
        "guarantee": f"none: the threshold was chosen by criterion {criterion!r} on this sample ({note})",
        "method": f"criterion {criterion!r} (assurance/analysis/criteria.py)",
        "split": split, "weights": weights, "monitor_model": {"sha256": monitor_model},
        "criterion": {"name": criterion, "recall": recall if criterion == "tnr-at-recall" else None, "note": note},
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }


def _scenarios(perturbations: Sequence[tuple[str, int]] | None) -> dict[str, Any]:
    """The calibration campaign's perturbations, severities and caps: clean only, or clean and each of
    ``perturbations`` at its severity (at most 3, the presets' severity)."""
    if perturbations is None:
        return {"perturbations": ("none",)}
    levels = {str(n): int(s) for n, s in perturbations if n != "none"}
    caps = {n: s for n, s in levels.items() if s < 3}
    return {"perturbations": ("none", *levels), "severities": (3,), "severity_caps": caps or None}


def calibrate_on_data(data: str | Path, monitor: str, *, rule: ThresholdRule, scenes: CalibrationScenes | None = None,
                      weights: str | dict[str, Any] | None = None, segmenter: Any = None,
                      progress: bool = False) -> dict[str, Any]:
    """Score every candidate of the scenes in ``data`` with ``monitor`` and calibrate it by ``rule``: the card
    document.

    The candidates, their truth and the scores come from the campaign's own task code, so a calibrated threshold
    means on test readouts what it meant here. ``scenes`` (:class:`CalibrationScenes`; None: its defaults): which
    scenes, the core model's configuration, and the perturbations: the scenes are clean (perturbation ``none``), or,
    with ``perturbations``, clean and under each of those.
    """
    scenes = scenes or CalibrationScenes()
    images, core, perturbations = scenes.images, scenes.core, scenes.perturbations
    _check_rates(rule.miss_rate, rule.confidence)
    base = parse_monitor_spec(monitor)
    if base is None:
        raise CalibrationError("'none' has no threshold to calibrate")

    config = CampaignConfig(**_scenarios(perturbations), monitors=(base.base.name,), images=images, weights=weights,
                            core=core or CoreConfig())
    tasks = plan(data, config)
    if not tasks:
        raise CalibrationError(f"{data}: no labelled scenes to calibrate on")
    loaded = segmenter is None
    if loaded:
        segmenter = load_model_spec(weights)
    network = network_record(segmenter, weights, loaded=loaded)  # an unidentified network is refused here

    monitor_model = build_monitor(base.base.name, labels=labels_of(segmenter)).model_sha256  # missing/altered: fails

    scores, unsafe, faults = [], [], []
    for task in bar(tasks, total=len(tasks), desc="calibration scenes", enabled=progress):
        rows = run_task(Task(task.perturbation, task.severity, task.sample), config, segmenter)
        faults += [r["fault"] for r in rows["images"] if r.get("fault")]
        scores += [r["score"] for r in rows["candidates"]]
        unsafe += [r["true_unsafe"] for r in rows["candidates"]]
    if faults:
        raise CalibrationError(f"{len(faults)} scene(s) failed: {faults[0]}")
    h = hashlib.sha256()
    samples = list({t.sample.key: t.sample for t in tasks}.values())  # each scene once, in the tasks' order
    for sample in samples:
        for f in (sample.image_path, sample.label_path):
            h.update(f"{Path(f).relative_to(data)}:{sha256_file(f)}\n".encode())
    body = calibration_body(
        scores, unsafe, monitor=base.base.name, rule=rule,
        split={"path": shown_path(data), "images": len(samples), "sha256": h.hexdigest(),
               "perturbation": ", ".join(p if p == "none" else f"{p} s{s}" for p, s in config.scenarios())},
        weights=network, monitor_model=monitor_model,
    )
    return card_document(body)


