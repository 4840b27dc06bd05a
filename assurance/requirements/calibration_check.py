"""EL-R16 on a campaign's readouts: the calibrated monitor's miss rate on the test split is within its card's
guarantee (judged by the Clopper-Pearson bound, not the point estimate)."""

from __future__ import annotations

from typing import Any

from assurance.analysis.intervals import BOUND_MISSED, decide_rate_bound
from assurance.requirements import records as rq


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
    rate at the card's confidence exceeds the card's miss rate (the test split shows the guarantee broken), at any
    number of candidates; otherwise insufficient below ``min_unsafe`` truly unsafe candidates. ``run_data`` (the
    manifest's ``data``): a run on the card's own calibration scenes, or on scenes whose meta declare a split
    other than ``test``, judges nothing (insufficient).
    """
    if card.body.get("miss_rate") is None or card.body.get("confidence") is None:
        chosen = (card.body.get("criterion") or {}).get("name", "another criterion")
        return rq.Evidence(f"miss rate of the calibrated monitor ({card.spec})", rq.INSUFFICIENT,
                           f"insufficient evidence: the card's threshold was chosen by criterion {chosen!r}, which "
                           "carries no miss-rate guarantee to test; calibrate with --criterion guarantee")
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
    eps, conf = float(card.body["miss_rate"]), float(card.body["confidence"])
    d = decide_rate_bound(k, n, eps, conf) if n else None
    if d is None or (n < max(1, int(min_unsafe)) and d.verdict != BOUND_MISSED):
        return rq.Evidence(name, rq.INSUFFICIENT, f"insufficient evidence: {n} truly unsafe candidate(s) on this "
                           f"split, fewer than the {int(min_unsafe)} that judge a miss rate (calibration_min_unsafe)")
    row = {"perturbation": perturbation, "unsafe": n, "accepted": k, "miss_rate": k / n, "bound": eps,
           "lower_bound": d.lower, "confidence": conf, "from": how}
    cols = tuple(row)
    summary = (f"{k} of {n} unsafe candidates accepted ({k / n:.3f}; one-sided {conf:.0%} lower bound {d.lower:.3f}) "
               f"with {how}")
    if d.verdict == BOUND_MISSED:  # the test split already shows the guarantee broken, whatever its size
        short = (f" (fewer than the {int(min_unsafe)} candidates that verify it, enough to show it missed)"
                 if n < int(min_unsafe) else "")
        return rq.Evidence(name, rq.FAIL, f"{summary} > {eps:g}{short}", (row,), cols)
    return rq.Evidence(name, rq.PASS, f"{summary} <= {eps:g}", (row,), cols)


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
