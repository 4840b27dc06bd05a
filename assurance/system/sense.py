"""Fitted files checked for sense when the system is built: a frame gate's and a calibration card's threshold must
lie where the scores they were fitted on lie.

A fitted file is hash-checked (``el.base.records``), but its hash covers only what it says about itself: anyone may edit
a threshold and compute the hash again. What such a file records about its own fit still bounds the threshold:

- a frame gate (``uav-el fit-gate``) is thresholded at the ``quantile`` of its validation frames' scores and
  records their ``median`` and ``max``: the threshold lies in [median, max] (a quantile >= 0.5), or at most the
  median (< 0.5), never above the highest score it was fitted on (1e300 passes every frame);
- a calibration card (``uav-el calibrate``) thresholds a monitor whose scores lie in a declared range
  (``Monitor.SCORE_RANGE``): a threshold at or above its top accepts every candidate, below its bottom rejects every
  one; its counts must add up (safe + unsafe = candidates, accepted unsafe <= unsafe and < the order statistic k,
  rejected safe <= safe) and its rates lie in (0, 1).

Neither file records the lowest score of its fit, so a threshold below it is caught only by the monitor's range or
the median. A forger who re-hashes the recorded range along with the threshold is not caught here: that needs
the scores themselves (the fit's data), which the system file does not carry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from el.base.errors import CalibrationError, FrameGateError
from el.classes.labels import LabelSet
from el.monitors import build_monitor
from el.monitors.calibration import load_calibration
from el.monitors.frame_gate import load_frame_gate


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def gate_problem(path: Path) -> str | None:
    """Why the frame gate at ``path`` makes no sense (one line naming the file), None when it does. The file is read
    with its own loader (``el.monitors.frame_gate.load_frame_gate``: format, hash, kind, statistics)."""
    gate = load_frame_gate(path)  # FrameGateError (a ValueError) naming the file when it cannot be used
    body, threshold = gate.body, gate.threshold
    val = body.get("validation") if isinstance(body.get("validation"), Mapping) else {}
    median, top, q = _number(val.get("median")), _number(val.get("max")), _number(body.get("quantile"))
    if median is None or top is None or q is None or not 0.0 < q < 1.0:
        return (f"{path}: records no score range of its fit (validation.median and .max, and a quantile in (0, 1)), "
                f"so its threshold {threshold!r} cannot be checked: fit the gate again (uav-el fit-gate)")
    if median > top:
        return f"{path}: validation median {median!r} above its max {top!r}: not the record of a fit"
    if threshold > top:
        return (f"{path}: threshold {threshold!r} lies above the highest score of the validation frames it was "
                f"fitted on ({top!r}): it would pass frames unlike any it was fitted on; fit the gate again")
    if (q >= 0.5 and threshold < median) or (q < 0.5 and threshold > median):
        side = "below" if q >= 0.5 else "above"
        return (f"{path}: threshold {threshold!r} lies {side} the median score of its validation frames ({median!r}) "
                f"though the file says it is their {q:g} quantile; fit the gate again")
    return None


def gate_refusal(path: Path) -> str | None:
    """:func:`gate_problem`, with a gate that cannot be used at all (unreadable, a FIFO, altered, inconsistent) its
    loader's line: why the gate at ``path`` is refused, None when it is not."""
    try:
        return gate_problem(path)
    except FrameGateError as exc:
        return str(exc)


def card_problem(path: Path, labels: LabelSet) -> str | None:
    """Why the calibration card at ``path`` makes no sense (one line naming the file), None when it does. Read with
    its own loader (``el.monitors.calibration.load_calibration``: format, hash, spec at the threshold)."""
    card = load_calibration(path)  # CalibrationError (a ValueError) naming the file when it cannot be used
    body, threshold = card.body, card.threshold
    for key, lo_open in (("miss_rate", True), ("confidence", True), ("bound", False)):
        value = body.get(key)
        v = _number(value)
        if value is not None and (v is None or not (0.0 < v < 1.0 if lo_open else 0.0 <= v <= 1.0)):
            return f"{path}: {key} = {value!r}: must be a number in {'(0, 1)' if lo_open else '[0, 1]'}"
    counts = body.get("counts")
    if isinstance(counts, Mapping):
        why = _counts_problem(counts, body.get("order_statistic_k"))
        if why:
            return f"{path}: counts {why}: not the record of a calibration"
    score_range = _score_range(card.monitor, labels)
    if score_range is not None:
        lo, hi = score_range
        if not lo <= threshold < hi:
            effect = "accept every candidate" if threshold >= hi else "reject every candidate"
            return (f"{path}: threshold {threshold!r} lies outside the score range [{lo:g}, {hi:g}] of its monitor "
                    f"{card.monitor!r}, so it was fitted on no score of it (it would {effect}); calibrate again "
                    "(uav-el calibrate)")
    return None


def _counts_problem(counts: Mapping[str, Any], k: Any) -> str | None:
    """Why a card's ``counts`` (and order statistic ``k``) cannot be those of one calibration, None when they can."""
    names = ("candidates", "unsafe", "safe", "unsafe_accepted", "safe_rejected")
    values = {n: counts.get(n) for n in names}
    if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in values.values()):
        return "must be integers >= 0 (" + ", ".join(names) + ")"
    if values["safe"] + values["unsafe"] != values["candidates"]:
        return f"safe {values['safe']} + unsafe {values['unsafe']} != candidates {values['candidates']}"
    if values["unsafe_accepted"] > values["unsafe"] or values["safe_rejected"] > values["safe"]:
        return "count more accepted unsafe or rejected safe candidates than there are"
    if isinstance(k, int) and not isinstance(k, bool) and not values["unsafe_accepted"] < k <= values["unsafe"]:
        return (f"order statistic k = {k} is not in ({values['unsafe_accepted']}, {values['unsafe']}] (the threshold "
                "lies below the k-th smallest unsafe score)")
    return None


def _score_range(monitor: str, labels: LabelSet) -> tuple[float, float] | None:
    """The scores the card's monitor can give (its class's ``SCORE_RANGE``), None when it cannot be built here (the
    command that runs it names why) or declares none."""
    try:
        built = build_monitor(monitor, labels=labels)
    except (ValueError, TypeError, OSError):
        return None
    lo, hi = getattr(type(built), "SCORE_RANGE", (-math.inf, math.inf))
    return None if (math.isinf(lo) and math.isinf(hi)) else (float(lo), float(hi))


def check_fitted(system: Any, labels: LabelSet, *, gate: Path | None = None) -> None:
    """Refuse a system whose frame gate (``[monitor] gate``, or ``gate`` given on the command line) or calibration
    card (``[monitor] calibration``) makes no sense: ``SystemFileError`` naming the system file, the key and the
    fitted file. A file that cannot be read at all is the same error (its loader's line)."""
    gate_key = "monitor.gate"
    if gate is None and system.get(gate_key) is not None and str(system.get(gate_key)) != "none":
        gate = system.path_of(gate_key)
    checks = []
    if gate is not None and Path(gate).is_file():
        checks.append((gate_key, lambda: gate_problem(Path(gate))))
    card = system.path_of("monitor.calibration")
    if card is not None and card.is_file():
        checks.append(("monitor.calibration", lambda: card_problem(card, labels)))
    for key, check in checks:
        try:
            why = check()
        except (FrameGateError, CalibrationError) as exc:
            why = str(exc)
        if why:
            raise system.error(key, why)
