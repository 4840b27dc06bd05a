"""Calibration cards: a monitor's threshold chosen on held-out data, with the guarantee it carries.

``uav-el calibrate`` (``assurance.calibration``) writes the card; the flight code only reads it. A card
is JSON ``{"format", "body", "sha256"}`` where ``sha256`` is the SHA-256 of the body's canonical JSON
(sorted keys, no spaces): an altered or truncated card is refused, as altered weights are. The body
names the monitor (``monitor``, at its default threshold), the calibrated ``threshold``, the
calibrated ``spec`` (the monitor with that threshold), the miss rate, confidence and bound, the
split, hashes and counts.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from el.monitors.spec import parse_monitor_spec

CARD_FORMAT = "uav-el-calibration/1"


class CalibrationError(ValueError):
    """A calibration card that cannot be used (missing, unreadable, altered, inconsistent)."""


def body_sha256(body: dict[str, Any]) -> str:
    """SHA-256 of a card body's canonical JSON."""
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def card_document(body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a card with this body (format and hash added)."""
    return {"format": CARD_FORMAT, "body": body, "sha256": body_sha256(body)}


@dataclass(frozen=True)
class CalibrationCard:
    """A checked calibration card (``load_calibration``)."""

    path: str
    sha256: str
    body: dict[str, Any]

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
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CalibrationError(f"{p}: cannot read the calibration card: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"{p}: not a calibration card (bad JSON: {exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != CARD_FORMAT or not isinstance(doc.get("body"), dict):
        raise CalibrationError(f"{p}: not a calibration card (format {CARD_FORMAT!r} expected)")
    body = doc["body"]
    try:
        digest = body_sha256(body)
    except ValueError as exc:
        raise CalibrationError(f"{p}: calibration card body is not plain JSON ({exc})") from None
    if digest != doc.get("sha256"):
        raise CalibrationError(f"{p}: calibration card altered: SHA-256 of its body is {digest[:12]}..., "
                               f"recorded {str(doc.get('sha256'))[:12]}...")
    try:
        spec = parse_monitor_spec(body["spec"])
        base = parse_monitor_spec(body["monitor"])
        threshold = float(body["threshold"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{p}: calibration card without a valid monitor and threshold ({exc})") from None
    if spec is None or base is None or spec.base != base.base or spec.threshold not in (threshold, None):
        raise CalibrationError(f"{p}: calibration card's spec {body['spec']!r} is not {body['monitor']!r} at "
                               f"threshold {threshold!r}")
    return CalibrationCard(str(p), digest, body)
