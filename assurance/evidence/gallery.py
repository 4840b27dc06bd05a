"""Pictures of the evidence report: the perturbation gallery and decisions drawn on their images.

Every picture is rebuilt from the run: the campaign's HD test image, perturbed with the campaign's own
per-task seed (``assurance.campaign.run.task_seed``), so the picture shows the very input the campaign
evaluated; the decision is drawn with ``assurance.evidence.overlay.draw_decision`` from the readouts
(candidates, verdicts, default area). Thumbnails are embedded as JPEG data URIs. When the data set
is gone the decision is drawn on a grey background and the caption says so.
"""

from __future__ import annotations

import base64
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from assurance.campaign.readouts import image_size
from assurance.campaign.task import frame_identity, task_seed
from assurance.dataio.layouts import DataSpec, iter_samples
from assurance.dataio.uavid import Sample, read_image
from assurance.evidence.overlay import draw_decision
from assurance.perturbations import perturb
from el.monitors.walk import ALL_REJECTED

GALLERY_SEVERITY = 3


def jpeg_uri(rgb: np.ndarray, width: int, quality: int = 85) -> str:
    """An RGB uint8 image, resized to ``width`` pixels wide, as a JPEG data URI."""
    h, w = rgb.shape[:2]
    if w > width:
        rgb = cv2.resize(rgb, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("could not encode a JPEG thumbnail")
    return "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


class Scenes:
    """The run's test images by key, perturbed as the campaign did (one cached at a time)."""

    def __init__(self, data: str | Path | DataSpec, seed: int) -> None:
        self.data = data if isinstance(data, DataSpec) else Path(data)
        self.seed = int(seed)
        self.error = ""
        self.samples: dict[str, Sample] = {}
        try:
            self.samples = {s.key: s for s in iter_samples(self.data, require_labels=False)}
        except Exception as exc:  # the data set moved or was deleted since the run
            self.error = f"test images not available ({exc})"
        self._cache: tuple[tuple[str, str, int], np.ndarray] | None = None

    def image(self, key: str, perturbation: str, severity: int) -> np.ndarray | None:
        """The perturbed HD frame the campaign evaluated, or None when it cannot be read."""
        wanted = (key, perturbation, int(severity))
        if self._cache is not None and self._cache[0] == wanted:
            return self._cache[1]
        sample = self.samples.get(key)
        if sample is None:
            return None
        try:
            rgb = read_image(sample.image_path)
            rng = np.random.default_rng(task_seed(self.seed, frame_identity(rgb), perturbation, int(severity)))
            hd = perturb(rgb, perturbation, int(severity), rng)
        except Exception as exc:
            self.error = f"{sample.image_path}: {exc}"
            return None
        self._cache = (wanted, hd)
        return hd


def perturbation_gallery(scenes: Scenes, key: str | None, scenarios: Sequence[tuple[str, int]], *,
                         width: int = 300) -> list[dict[str, str]]:
    """One test image under each perturbation the run evaluated (``scenarios``: its (perturbation, severity)
    pairs), at severity 3 where it ran at 3, else at the highest severity it ran at: [{name, uri, caption}]."""
    if key is None or key not in scenes.samples:
        return []
    ran: dict[str, set[int]] = {}
    for name, sev in scenarios:
        ran.setdefault(str(name), set()).add(int(sev))
    out = []
    for name, sevs in ran.items():
        sev = GALLERY_SEVERITY if GALLERY_SEVERITY in sevs else max(sevs)
        hd = scenes.image(key, name, sev)
        if hd is None:
            continue
        out.append({"name": name, "uri": jpeg_uri(hd, width),
                    "caption": f"{name}, severity {sev}" if name != "none" else "none (unperturbed)"})
    return out


def _f(v: Any, digits: int = 2) -> str:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "n/a"
    return f"{x:.{digits}f}" if math.isfinite(x) else "n/a"


def decision_record(image_row: Any, cands: Any) -> dict[str, Any]:
    """The decision dict ``draw_decision`` reads, rebuilt from one images-table row and its candidates."""
    W, H = image_size(image_row)
    sel = int(image_row["selected"])
    candidates = []
    for c in cands.sort_values("rank").itertuples(index=False):
        verdict = ({"name": image_row["monitor"], "accepted": bool(c.accepted), "reason": str(c.reason),
                    "seconds": float(c.seconds)} if bool(c.examined) else None)
        candidates.append({"rank": int(c.rank), "x": float(c.x), "y": float(c.y), "radius_px": float(c.radius_px),
                           "monitor": verdict})
    return {"action": str(image_row["action"]), "reason": str(image_row["reason"]),
            "selected": None if sel < 0 else sel, "candidates": candidates,
            "default_area": {"x": float(image_row["default_x"]), "y": float(image_row["default_y"]),
                             "radius_px": float(image_row["default_r"])},
            "input": {"width": W, "height": H}}


def draw(scenes: Scenes, image_row: Any, cands: Any, *, width: int = 480) -> tuple[str, bool]:
    """(JPEG data URI of the decision drawn on its perturbed image, whether the real image was used)."""
    record = decision_record(image_row, cands)
    hd = scenes.image(str(image_row["key"]), str(image_row["perturbation"]), int(image_row["severity"]))
    if hd is not None and (hd.shape[1], hd.shape[0]) != (record["input"]["width"], record["input"]["height"]):
        hd = None
    picture = draw_decision(record, image=hd)
    return jpeg_uri(picture, width), hd is not None


def candidate_rows(cands: Any, *, selected_only: bool = False, unexamined: int = 2) -> list[dict[str, str]]:
    """Caption rows of a decision's candidates, as strings: the selected one only with ``selected_only``,
    else those the walk examined and the first ``unexamined`` it did not reach."""
    rows = []
    left = unexamined
    for c in cands.sort_values("rank").itertuples(index=False):
        if selected_only and not c.selected:
            continue
        if not c.examined:
            if left <= 0:
                continue
            left -= 1
        verdict = ("accepted" if c.accepted else "rejected") if c.examined else "not examined"
        rows.append({"rank": str(int(c.rank)), "hazard": _f(c.hazard), "true_hazard": _f(c.true_hazard),
                     "unsafe": "yes" if bool(c.true_unsafe) else "no", "forbidden": bool(c.true_unsafe),
                     "clearance": _f(c.clearance_m, 1) if np.isfinite(float(c.clearance_m)) else "n/a",
                     "verdict": verdict, "selected": "yes" if bool(c.selected) else "",
                     "reason": str(c.reason) if c.examined else ""})
    return rows


def walk_summary(cands: Any, selected: int, reason: str = ALL_REJECTED) -> str:
    """What the walk did before the decision, in one line; ``reason``: the decision's (a default action taken before
    any walk, outside the declared domain or refused by the frame gate, says so, not that the monitor rejected)."""
    n = len(cands)
    if n == 0:
        return "no candidate found"
    rejected = cands[cands["examined"].astype(bool) & ~cands["accepted"].astype(bool)].sort_values("rank")
    reasons = Counter(str(r) for r in rejected["reason"])
    common = f"; most frequent reason: {reasons.most_common(1)[0][0]}" if reasons else ""
    if selected < 0 and reason != ALL_REJECTED:
        accepted = int((cands["examined"].astype(bool) & cands["accepted"].astype(bool)).sum())
        return (f"the default action before any landing ({reason.split(':', 1)[0]}); of the {n} candidates, judged "
                f"for the readouts only, {accepted} accepted and {len(rejected)} rejected")
    if selected < 0:
        return f"all {len(rejected)} of {n} candidates rejected{common}"
    if selected == 0:
        return f"top-ranked of {n} candidates accepted"
    return f"candidates 0-{selected - 1} rejected before it ({n} in all){common}"


def decision_examples(scenes: Scenes, images: Any, candidates: Any, picks: Iterable[tuple[Any, str]], *,
                      width: int = 480, also: dict[tuple, list[str]] | None = None,
                      compact: bool = False) -> list[dict[str, Any]]:
    """Pictures and captions of chosen decisions: ``picks`` = (images-table row, why it is shown)."""
    groups = {}
    if len(candidates):
        groups = {k: g for k, g in candidates.groupby(["perturbation", "severity", "monitor", "key"], sort=False)}
    out = []
    for row, why in picks:
        key = (row["perturbation"], row["severity"], row["monitor"], row["key"])
        cands = groups.get(key, candidates.iloc[:0] if len(candidates) else _empty_candidates())
        uri, real = draw(scenes, row, cands, width=width)
        rows = candidate_rows(cands, selected_only=compact)
        sel = int(row["selected"])
        decision = (f"land on candidate {sel}" if row["action"] == "land" else "default action (parachute)")
        if bool(row["decision_unsafe"]) and row["action"] != "land":
            decision += " over a forbidden area"
        monitors = (also or {}).get((row["perturbation"], int(row["severity"]), row["key"], sel), [row["monitor"]])
        out.append({
            "title": f"{row['key']}: {row['perturbation']} (s{int(row['severity'])})",
            "why": why, "uri": uri, "real_image": real,
            "monitor": row["monitor"], "monitors": ", ".join(monitors),
            "decision": decision, "reason": str(row["reason"]),
            "h_decision": _f(row["h_decision"]), "h_default": _f(row["h_default"]),
            "unsafe": bool(row["decision_unsafe"]),
            "candidates": rows,
            "more": (f"{len(cands) - len(rows)} more candidate(s) the walk did not reach"
                     if not compact and len(cands) > len(rows) else ""),
            "walk": walk_summary(cands, sel, str(row["reason"])),
        })
    return out


def _empty_candidates() -> Any:
    import pandas as pd

    return pd.DataFrame(columns=["rank", "x", "y", "radius_px", "hazard", "true_hazard", "true_unsafe",
                                 "clearance_m", "accepted", "reason", "seconds", "selected", "examined"])
