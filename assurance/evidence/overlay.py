"""Draw a landing decision on the image or on the colour labels, like the paper's Figure 2.

Numbered candidate discs coloured by status (accepted green, rejected red, unmonitored yellow,
not examined grey; the selected one thicker), the default area in blue, the unreachable top
stripes shaded, and the decision with its reason as text. Returns RGB uint8 (H, W, 3).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import cv2
import numpy as np

from el.base.decision import Decision
from el.classes.labels import ids_to_colors
from el.geometry.camera import CameraGeometry, Pose
from el.geometry.config import CoreConfig

# RGB colours of the candidate statuses (the legend uses the same table).
STATUS_COLOURS: dict[str, tuple[int, int, int]] = {
    "accepted": (40, 210, 40),
    "rejected": (230, 30, 30),
    "unmonitored": (250, 220, 0),
    "not examined": (160, 160, 160),
}
DEFAULT_COLOUR = (40, 110, 255)
_SHIFT = 4  # sub-pixel precision of cv2 drawing: coordinates times 2**4


def candidate_status(candidate: dict[str, Any], any_monitored: bool) -> str:
    """"accepted", "rejected", "unmonitored" (no monitor in the pipeline) or "not examined"."""
    verdict = candidate.get("monitor")
    if verdict is None:
        return "not examined" if any_monitored else "unmonitored"
    return "accepted" if verdict.get("accepted") else "rejected"


def _first_reachable_row(d: dict[str, Any], W: int, H: int) -> int:
    """The first reachable row of the camera, pose and reach the decision records (they set the unreachable
    stripes, el.geometry.camera.CameraGeometry.unreachable_stripes); the nominal ones where it records none."""
    if W < 8 or H < 8:
        return 0
    try:
        core = CoreConfig.from_dict(dict((d.get("config") or {}).get("core") or {}))
        pose = (d.get("input") or {}).get("pose")
        if pose:
            core = replace(core, pose=Pose(height_m=pose["height_m"], pitch_deg=pose["pitch_deg"]))
        return core.geometry(W, H).first_reachable_row
    except (TypeError, ValueError, KeyError, AttributeError):
        return CameraGeometry(width=W, height=H).first_reachable_row


def draw_decision(
    decision: Decision | dict[str, Any],
    *,
    image: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    labels_alpha: float = 0.0,
    label_set: Any = None,
) -> np.ndarray:
    """Draw ``decision`` (a Decision or its dict) and return an RGB uint8 (H, W, 3) picture.

    The background is ``image`` (RGB uint8) if given, else the colour-coded ``labels`` (class ids
    (H, W)), else grey. With both, ``labels_alpha`` > 0 blends the label colours over the image.
    """
    d = decision.to_dict() if isinstance(decision, Decision) else decision
    paint = ids_to_colors if label_set is None else label_set.ids_to_colors  # the ids' own palette
    canvas = _background(d, image, labels, labels_alpha, paint)
    H, W = canvas.shape[:2]
    s = max(W, H) / 1024.0
    thick = max(2, int(round(2 * s)))

    first = _first_reachable_row(d, W, H)
    if first > 0:
        top = canvas[:first].astype(np.float32)
        canvas[:first] = (0.45 * top + 0.55 * np.array([30, 30, 60], np.float32)).astype(np.uint8)
        cv2.line(canvas, (0, first), (W - 1, first), (255, 255, 255), max(1, thick // 2), cv2.LINE_AA)
        _text(canvas, "unreachable", (int(8 * s), first - int(8 * s)), 0.5 * s, (230, 230, 230))

    area = d.get("default_area") or {}
    if area:
        t = 3 * thick if d.get("action") == "default" else thick
        _circle(canvas, area["x"], area["y"], area["radius_px"], DEFAULT_COLOUR, t)
        _text(canvas, "default", (int(area["x"] - 28 * s), int(area["y"] + 5 * s)), 0.5 * s, DEFAULT_COLOUR)

    cands = d.get("candidates") or []
    any_monitored = any(c.get("monitor") is not None for c in cands)
    selected = d.get("selected")
    for c in reversed(cands):  # rank 0 drawn last, on top
        colour = STATUS_COLOURS[candidate_status(c, any_monitored)]
        t = 3 * thick if c.get("rank") == selected else thick
        _circle(canvas, c["x"], c["y"], c["radius_px"], colour, t)
        label = str(c.get("rank", "?"))
        scale = 0.6 * s
        (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, max(1, thick))
        _text(canvas, label, (int(c["x"] - tw / 2), int(c["y"] + th / 2)), scale, colour)

    action = str(d.get("action", "?")).upper()
    reason = str(d.get("reason", ""))
    head = f"{action} on #{selected} ({reason})" if selected is not None else f"{action} ({reason})"
    _text(canvas, head, (int(10 * s), int(28 * s)), 0.8 * s, (255, 255, 255))
    _legend(canvas, s, cands, any_monitored)
    return canvas


def _background(
    d: dict[str, Any], image: np.ndarray | None, labels: np.ndarray | None, alpha: float, paint: Any = ids_to_colors
) -> np.ndarray:
    if image is not None:
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"image must be RGB uint8 (H, W, 3), got {image.dtype} {image.shape}")
        canvas = image.copy()
        if labels is not None and alpha > 0:
            colours = paint(labels).astype(np.float32)
            if colours.shape != canvas.shape:
                raise ValueError(f"labels {colours.shape[:2]} and image {canvas.shape[:2]} differ in size")
            canvas = ((1 - alpha) * canvas + alpha * colours).astype(np.uint8)
        return canvas
    if labels is not None:
        return np.ascontiguousarray(paint(labels))
    info = d.get("input") or {}
    W, H = int(info.get("width", 1024)), int(info.get("height", 576))
    return np.full((H, W, 3), 96, dtype=np.uint8)


def _circle(canvas: np.ndarray, x: float, y: float, r: float, colour, thickness: int) -> None:
    f = 1 << _SHIFT
    cv2.circle(canvas, (int(round(x * f)), int(round(y * f))), max(1, int(round(r * f))),
               (0, 0, 0), thickness + 2, cv2.LINE_AA, _SHIFT)
    cv2.circle(canvas, (int(round(x * f)), int(round(y * f))), max(1, int(round(r * f))),
               tuple(int(v) for v in colour), thickness, cv2.LINE_AA, _SHIFT)


def _text(canvas: np.ndarray, text: str, org: tuple[int, int], scale: float, colour) -> None:
    t = max(1, int(round(2 * scale)))
    cv2.putText(canvas, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), t + 2, cv2.LINE_AA)
    rgb = tuple(int(v) for v in colour)
    cv2.putText(canvas, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, rgb, t, cv2.LINE_AA)


def _legend(canvas: np.ndarray, s: float, cands: list[dict[str, Any]], any_monitored: bool) -> None:
    shown = sorted({candidate_status(c, any_monitored) for c in cands}, key=list(STATUS_COLOURS).index)
    entries = [(name, STATUS_COLOURS[name]) for name in shown] + [("default area", DEFAULT_COLOUR)]
    H = canvas.shape[0]
    y = H - int(10 * s) - int(22 * s) * (len(entries) - 1)
    for name, colour in entries:
        cv2.rectangle(canvas, (int(10 * s), y - int(12 * s)), (int(24 * s), y), colour, -1)
        _text(canvas, name, (int(30 * s), y), 0.5 * s, (255, 255, 255))
        y += int(22 * s)
