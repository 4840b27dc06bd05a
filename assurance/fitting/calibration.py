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
import math
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import binom

from assurance.paths import shown_path
from el.monitors.calibration import CalibrationError, card_document
from el.monitors.spec import THRESHOLD, parse_monitor_spec

__all__ = ["CalibrationError", "calibrate_threshold", "calibration_body", "check_calibrated_miss_rate",
           "min_unsafe_needed"]


def _check_rates(miss_rate: float, confidence: float) -> None:
    for name, v in (("miss rate", miss_rate), ("confidence", confidence)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 < float(v) < 1.0:
            raise CalibrationError(f"{name} must lie in (0, 1), got {v!r}")


def min_unsafe_needed(miss_rate: float, confidence: float) -> int:
    """Fewest unsafe calibration candidates that can certify ``miss_rate`` at ``confidence`` (k = 1)."""
    _check_rates(miss_rate, confidence)
    return int(math.ceil(math.log(1.0 - confidence) / math.log(1.0 - miss_rate)))


def calibrate_threshold(unsafe_scores: Any, miss_rate: float, confidence: float) -> dict[str, Any]:
    """The threshold with the guarantee above, from the scores of the truly unsafe calibration candidates.

    Returns ``{"threshold", "k", "n", "bound", "accepted"}``: ``bound`` is the Clopper-Pearson upper
    bound of the miss rate at ``confidence`` (``<= miss_rate``), ``accepted`` the unsafe calibration
    candidates the threshold accepts.
    """
    from assurance.analysis.metrics import clopper_pearson_upper

    _check_rates(miss_rate, confidence)
    s = np.sort(np.asarray(unsafe_scores, dtype=np.float64))
    if s.ndim != 1 or np.isnan(s).any():
        raise CalibrationError("unsafe scores must be a one-dimensional array without NaN")
    n = int(s.size)
    delta = 1.0 - confidence
    # largest k in 1..n with P(Bin(n, miss_rate) <= k - 1) <= delta
    cdf = binom.cdf(np.arange(n), n, miss_rate)  # cdf[j] = P(Bin <= j), j = k - 1
    ok = np.flatnonzero(cdf <= delta)
    if n == 0 or ok.size == 0:
        need = min_unsafe_needed(miss_rate, confidence)
        raise CalibrationError(f"{n} truly unsafe calibration candidate(s): at least {need} are needed to "
                               f"certify a miss rate of {miss_rate:g} at confidence {confidence:g}")
    k = int(ok[-1]) + 1
    threshold = float(np.nextafter(s[k - 1], -np.inf))
    if not math.isfinite(threshold):
        raise CalibrationError(f"the {k}-th smallest unsafe score is {s[k - 1]!r}: no finite threshold below it")
    accepted = int((s <= threshold).sum())
    return {"threshold": threshold, "k": k, "n": n, "accepted": accepted,
            "bound": clopper_pearson_upper(accepted, n, confidence)}


def calibration_body(scores: Any, unsafe: Any, *, monitor: str, miss_rate: float, confidence: float,
                     split: dict[str, Any], weights: dict[str, Any],
                     monitor_model: str | None = None) -> dict[str, Any]:
    """The card body: the calibrated threshold from the candidates' scores and truths, with what it rests on
    (``monitor_model``: the SHA-256 of the monitor's fitted model file, if it has one)."""
    base = parse_monitor_spec(monitor)
    if base is None:
        raise CalibrationError("'none' has no threshold to calibrate")
    base = base.base
    s = np.asarray(scores, dtype=np.float64)
    y = np.asarray(unsafe, dtype=bool)
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
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }


def calibrate_on_data(data: str | Path, monitor: str, *, miss_rate: float, confidence: float,
                      weights: str | dict[str, Any] | None = None, images: int | None = None, segmenter: Any = None,
                      core: Any = None, progress: bool = False) -> dict[str, Any]:
    """Score every candidate of the clean scenes in ``data`` with ``monitor`` and calibrate it: the card document.

    The candidates, their truth and the scores come from the campaign's own task code (perturbation
    ``none``), so a calibrated threshold means on test readouts what it meant here.
    """
    from assurance.campaign.run import CampaignConfig, Task, plan, run_task
    from assurance.fitting.network_identity import network_record
    from el.config import CoreConfig
    from el.hashing import sha256_file

    _check_rates(miss_rate, confidence)
    base = parse_monitor_spec(monitor)
    if base is None:
        raise CalibrationError("'none' has no threshold to calibrate")
    from el.monitors import build_monitor

    monitor_model = build_monitor(base.base.name).model_sha256  # a missing or altered model file fails here
    config = CampaignConfig(perturbations=("none",), monitors=(base.base.name,), images=images, weights=weights,
                            core=core or CoreConfig())
    tasks = plan(data, config)
    if not tasks:
        raise CalibrationError(f"{data}: no labelled scenes to calibrate on")
    loaded = segmenter is None
    if loaded:
        from assurance.system.model import load_model_spec

        segmenter = load_model_spec(weights)
    network = network_record(segmenter, weights, loaded=loaded)  # an unidentified network is refused here
    from assurance.progress import progress as bar

    scores, unsafe, faults = [], [], []
    for task in bar(tasks, total=len(tasks), desc="calibration scenes", enabled=progress):
        rows = run_task(Task(task.perturbation, task.severity, task.sample), config, segmenter)
        faults += [r["fault"] for r in rows["images"] if r.get("fault")]
        scores += [r["score"] for r in rows["candidates"]]
        unsafe += [r["true_unsafe"] for r in rows["candidates"]]
    if faults:
        raise CalibrationError(f"{len(faults)} scene(s) failed: {faults[0]}")
    h = hashlib.sha256()
    for t in tasks:
        for f in (t.sample.image_path, t.sample.label_path):
            h.update(f"{Path(f).relative_to(data)}:{sha256_file(f)}\n".encode())
    body = calibration_body(
        scores, unsafe, monitor=base.base.name, miss_rate=miss_rate, confidence=confidence,
        split={"path": shown_path(data), "images": len(tasks), "sha256": h.hexdigest(),
               "perturbation": "none"},
        weights=network,
        monitor_model=monitor_model,
    )
    return card_document(body)


def check_calibrated_miss_rate(candidates: Any, card: Any, perturbation: str = "none",
                               run_models: dict[str, str] | None = None, run_network: Any = False, *,
                               min_unsafe: int = 1, run_data: dict[str, Any] | None = None) -> Any:
    """EL-R16: on a campaign's readouts (the test split), the calibrated monitor's empirical miss rate (truly
    unsafe candidates it accepts) is at most the card's miss rate.

    Reads the calibrated configuration's rows, or else the base monitor's scores judged at the card's threshold.
    ``run_models`` (the run manifest's ``monitor_models``): a card calibrated on another fitted model than
    the one that scored the rows fails; its threshold does not mean the same on that model's scores.
    ``run_network`` (the manifest's ``weights.sha256``): a card calibrated on another network fails, and a run
    that does not record its network is insufficient evidence (False: not checked, for callers without a run).

    Judged by the bound, not the point estimate: failed when the one-sided Clopper-Pearson lower bound of the miss
    rate at the card's confidence exceeds the card's miss rate (the test split shows the guarantee broken);
    insufficient below ``min_unsafe`` truly unsafe candidates. ``run_data`` (the manifest's ``data``): a run on
    the card's own calibration scenes, or on scenes whose meta declare a split other than ``test``, judges
    nothing (insufficient).
    """
    from assurance.analysis.metrics import clopper_pearson_interval
    from assurance.requirements import records as rq

    name = f"miss rate of the calibrated monitor ({card.spec}) <= {card.body['miss_rate']:g}"
    if candidates is None or len(candidates) == 0:
        return rq.Evidence(name, rq.INSUFFICIENT, "insufficient evidence: no candidates in the run")
    sub = candidates[(candidates["perturbation"] == perturbation) & (candidates["monitor"] == card.spec)]
    how = "its own verdicts"
    if sub.empty and "score" in candidates.columns:
        sub = candidates[(candidates["perturbation"] == perturbation) & (candidates["monitor"] == card.monitor)]
        sub = sub.assign(accepted=~(sub["score"].astype(float) > card.threshold))
        how = f"{card.monitor}'s scores at threshold {card.threshold:.6g}"
    if sub.empty:
        return rq.Evidence(name, rq.INSUFFICIENT, f"insufficient evidence: neither {card.spec!r} nor the scores "
                           f"of {card.monitor!r} were recorded under {perturbation!r}")
    used = str(sub["monitor"].iloc[0])
    if run_network is not False and run_network != card.network_sha256:
        if not run_network:
            return rq.Evidence(name, rq.INSUFFICIENT, "insufficient evidence: the run does not record the network "
                               "it segmented with, so it cannot be shown to be the card's")
        return rq.Evidence(name, rq.FAIL, f"the card was calibrated on network {str(card.network_sha256)[:12]}, the "
                           f"run segmented with {str(run_network)[:12]}: recalibrate or re-run the campaign")
    card_model = (card.body.get("monitor_model") or {}).get("sha256")
    if run_models is None and card_model:
        return rq.Evidence(name, rq.INSUFFICIENT, "insufficient evidence: the run's manifest does not record "
                           "its monitors' models, so it cannot be shown to have scored with the card's")
    if run_models is not None and (run_models.get(used) or None) != card_model:
        return rq.Evidence(name, rq.FAIL, f"the card was calibrated on monitor model {card_model!r}, the run's "
                           f"{used!r} scored with {run_models.get(used)!r}: recalibrate or re-run the campaign")
    wrong_split = _split_problem(card, run_data)
    if wrong_split:
        return rq.Evidence(name, rq.INSUFFICIENT, f"insufficient evidence: {wrong_split}")
    unsafe = sub[sub["true_unsafe"].astype(bool)]
    n, k = len(unsafe), int(unsafe["accepted"].astype(bool).sum())
    if n < max(1, int(min_unsafe)):
        return rq.Evidence(name, rq.INSUFFICIENT, f"insufficient evidence: {n} truly unsafe candidate(s) on this "
                           f"split, fewer than the {int(min_unsafe)} that judge a miss rate (calibration_min_unsafe)")
    eps, conf = float(card.body["miss_rate"]), float(card.body["confidence"])
    lower = clopper_pearson_interval(k, n, 2 * conf - 1)[0]  # one-sided at the card's confidence
    row = {"perturbation": perturbation, "unsafe": n, "accepted": k, "miss_rate": k / n, "bound": eps,
           "lower_bound": lower, "confidence": conf, "from": how}
    cols = tuple(row)
    summary = (f"{k} of {n} unsafe candidates accepted ({k / n:.3f}; one-sided {conf:.0%} lower bound {lower:.3f}) "
               f"with {how}")
    status = rq.PASS if lower <= eps else rq.FAIL
    return rq.Evidence(name, status, summary + (" <= " if status == rq.PASS else " > ") + f"{eps:g}", (row,), cols)


def _split_problem(card: Any, run_data: dict[str, Any] | None) -> str | None:
    """Why the run's scenes cannot test the card (its own calibration scenes, or another split than test)."""
    if not run_data:
        return None
    if run_data.get("sha256") and run_data.get("sha256") == (card.body.get("split") or {}).get("sha256"):
        return "the run evaluated the scenes the card was calibrated on; run the campaign on the test split"
    splits = run_data.get("splits") or {}
    other = sorted(s for s in splits if s != "test")
    if other:
        return (f"the run's scenes declare the split(s) {', '.join(other)} (meta/*.json), not test: the card's "
                "guarantee is tested on scenes neither fitting nor calibration saw")
    return None
