"""How well the evidence a runtime monitor reads separates truly unsafe candidates from safe ones.

For every core-model candidate of a clean scene, the HD patch around its disc is segmented (the LHD
monitor's view) and three scores are read from the disc's pixels, higher meaning "more likely unsafe":

- ``max_forbidden_probability``: the largest probability of any forbidden class at any disc pixel;
- ``lhd_margin``: the largest (top forbidden probability - top safe probability) over the disc. LHD
  rejects a disc exactly when this is >= 0, so its threshold 0 is the LHD rule;
- ``forbidden_fraction``: the share of disc pixels whose top class is forbidden (ties forbidden).

Their AUROC for "the disc holds a forbidden ground-truth pixel" is reported with a 95% bootstrap interval
over **scenes** (candidates of one scene are not independent; ``assurance.analysis.scores.grouped_auroc_ci``,
the harness's one bootstrap), beside the LHD rule's recall and false-positive rate. With no separation (AUROC
near 0.5) no threshold can make a monitor add safety, which is why a model card records this figure.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from assurance.analysis.intervals import BOOTSTRAP_METHOD
from assurance.analysis.scores import auroc as scores_auroc
from assurance.analysis.scores import grouped_auroc_ci
from el.landing.forbidden import top_scores
from el.monitors.lhd import disc_pixels
from el.monitors.patches import extract_patch
from el.segmentation.contract import labels_of

SCORES = ("max_forbidden_probability", "lhd_margin", "forbidden_fraction")


def disc_scores(segmenter: Any, rgb: np.ndarray, disc: Any, *, margin: float = 0.25) -> dict[str, float]:
    """The three evidence scores of one candidate's disc on its HD patch (see the module docstring)."""
    patch = extract_patch(rgb, disc, margin=margin)
    labels = labels_of(segmenter)  # the network's classes: which of its outputs are forbidden
    pixels = disc_pixels(segmenter.predict_patch(patch.rgb), patch.disc_mask, labels)  # (C, m)
    top_f, top_s = top_scores(pixels, labels)
    return {"max_forbidden_probability": float(top_f.max()), "lhd_margin": float((top_f - top_s).max()),
            "forbidden_fraction": float((top_f >= top_s).mean())}


def auroc(unsafe: np.ndarray, score: np.ndarray) -> float | None:
    """Area under the ROC curve (ties count one half, :func:`assurance.analysis.scores.auroc`); None without both
    classes."""
    area = scores_auroc(score, unsafe)
    return None if math.isnan(area) else area


def separation(rows: list[dict[str, Any]], *, n_boot: int = 1000, seed: int = 0, conf: float = 0.95
               ) -> dict[str, Any]:
    """AUROC of each score with a scene-level bootstrap interval, and the LHD rule's recall / FP rate.

    ``rows``: one per candidate, with ``scene`` (any hashable), ``unsafe`` (bool) and the scores.
    """
    if not rows:
        return {"candidates": 0, "unsafe": 0, "scores": {}, "lhd_rule": None}
    unsafe = np.array([r["unsafe"] for r in rows], bool)
    scenes = np.array([str(r["scene"]) for r in rows])
    out: dict[str, Any] = {"candidates": int(unsafe.size), "unsafe": int(unsafe.sum()),
                           "scenes": int(np.unique(scenes).size),
                           "bootstrap": {"resamples": n_boot, "unit": "scene", "seed": seed, "conf": conf,
                                         "method": BOOTSTRAP_METHOD},
                           "scores": {}}
    for name in SCORES:
        score = np.array([r[name] for r in rows], np.float64)
        point = auroc(unsafe, score)
        lo, hi = grouped_auroc_ci(scenes, score, unsafe, n_boot=n_boot, seed=seed, conf=conf) if point is not None \
            else (math.nan, math.nan)
        out["scores"][name] = {"auroc": point, "ci": [lo if math.isfinite(lo) else None,
                                                      hi if math.isfinite(hi) else None]}
    rejected = np.array([r["lhd_margin"] >= 0 for r in rows], bool)
    out["lhd_rule"] = {
        "recall": float(rejected[unsafe].mean()) if unsafe.any() else None,
        "fp_rate": float(rejected[~unsafe].mean()) if (~unsafe).any() else None,
    }
    return out


def describe_separation(sep: dict[str, Any]) -> str:
    """One line for the model card printout."""
    if not sep or not sep.get("scores"):
        return "no candidates"
    s = sep["scores"]["max_forbidden_probability"]
    rule = sep["lhd_rule"] or {}

    def f(v: float | None) -> str:
        return "-" if v is None else f"{v:.3f}"

    return (f"AUROC of the HD disc's max forbidden probability for 'truly unsafe' {f(s['auroc'])} "
            f"[{f(s['ci'][0])}, {f(s['ci'][1])}] ({sep['unsafe']} unsafe of {sep['candidates']}); "
            f"LHD rule recall {f(rule.get('recall'))}, FP rate {f(rule.get('fp_rate'))}")
