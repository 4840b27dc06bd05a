"""Calibration cards: a monitor's threshold chosen on held-out data, with the guarantee it carries.

``uav-el calibrate`` (``assurance.fitting.calibration``) writes the card; the flight code only reads it. A card
is JSON ``{"format", "body", "sha256"}`` where ``sha256`` is the SHA-256 of the body's canonical JSON
(sorted keys, no spaces): an altered or truncated card is refused, as altered weights are. The body
names the monitor (``monitor``, at its default threshold), the calibrated ``threshold``, the
calibrated ``spec`` (the monitor with that threshold), the miss rate, confidence and bound, the
split, hashes and counts, and (``monitor_model``) the SHA-256 of the fitted file the monitor's scores
rest on, if any: :func:`check_card_monitor` refuses to run the card's threshold on another model, and
:func:`check_card_spec` a spec of the card's monitor that carries a threshold of its own other than the card's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from el.base.errors import CalibrationError
from el.base.records import HashedRecord, short
from el.monitors.spec import monitor_name, parse_monitor_spec

CARD_FORMAT = "uav-el-calibration/1"


@dataclass(frozen=True)
class CalibrationCard(HashedRecord):
    """A checked calibration card (``load_calibration``)."""

    FORMAT: ClassVar[str] = CARD_FORMAT
    WHAT: ClassVar[str] = "calibration card"
    ERROR: ClassVar[type[ValueError]] = CalibrationError

    @property
    def spec(self) -> str:
        """The calibrated monitor spec, e.g. ``lhd:threshold=0.0123``."""
        return str(self.body["spec"])

    @property
    def monitor(self) -> str:
        """The monitor at its default threshold, e.g. ``lhd``."""
        return str(self.body["monitor"])

    @property
    def threshold(self) -> float:
        return float(self.body["threshold"])


def load_calibration(path: str | Path) -> CalibrationCard:
    """Read and check a card: format, hash of the body, and a spec that is the monitor at the threshold.

    Raises
    ------
    CalibrationError
        One line naming the file and the problem.
    """
    p = Path(path)
    body, digest = CalibrationCard.read_body(p)
    try:
        spec = parse_monitor_spec(body["spec"])
        base = parse_monitor_spec(body["monitor"])
        threshold = float(body["threshold"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{p}: calibration card without a valid monitor and threshold ({exc})") from None
    if spec is None or base is None or spec.base != base.base or spec.threshold not in (threshold, None):
        raise CalibrationError(f"{p}: calibration card's spec {body['spec']!r} is not {body['monitor']!r} at "
                               f"threshold {threshold!r}")
    model = body.get("monitor_model")
    if model is not None and not (isinstance(model, dict) and _is_digest_or_none(model.get("sha256"))):
        raise CalibrationError(f"{p}: calibration card's monitor_model must be {{\"sha256\": null or 64 hex "
                               f"digits}}, got {model!r}")
    return CalibrationCard(str(p), digest, body)


def _is_digest_or_none(value: object) -> bool:
    return value is None or (isinstance(value, str) and len(value) == 64
                             and all(c in "0123456789abcdef" for c in value))


def check_card_monitor(card: CalibrationCard, monitor: Any) -> None:
    """Refuse a card whose monitor rested on another fitted model than ``monitor`` (built from its spec).

    Raises
    ------
    CalibrationError
        The card records a model hash (``monitor_model.sha256``) that is not the monitor's, or the monitor
        rests on a model the card does not record (a card written before, or edited to hide it).
    """
    want = (card.body.get("monitor_model") or {}).get("sha256")
    have = getattr(monitor, "model_sha256", None)
    if want != have:
        raise CalibrationError(f"{card.path}: calibrated on monitor model {short(want)}, but the monitor runs "
                               f"{short(have)}: recalibrate (uav-el calibrate) for this model")


def check_card_spec(card: CalibrationCard, spec: Any) -> None:
    """Refuse ``spec`` unless ``card`` calibrates it: the card's monitor, with no threshold of its own (it then
    runs at the card's) or with exactly the card's. A user's ``lhd:threshold=X`` with no card is not checked.

    Raises
    ------
    CalibrationError
        One line naming the card, the spec and, for a threshold, both thresholds.
    """
    parsed = parse_monitor_spec(spec)
    if parsed is None or parsed.base != parse_monitor_spec(card.monitor).base:
        raise CalibrationError(f"{card.path}: calibrates {card.monitor!r}, not {monitor_name(spec)!r}")
    if parsed.threshold is not None and parsed.threshold != card.threshold:
        raise CalibrationError(f"{card.path}: monitor {parsed.name!r} has threshold {parsed.threshold!r}, but its "
                               f"calibration card has threshold {card.threshold!r}: run the card's spec "
                               f"{card.spec!r} or recalibrate (uav-el calibrate)")


def card_document(body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a card with this body (format and hash added)."""
    return CalibrationCard.document(body)
