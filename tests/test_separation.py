"""Separation of safe and unsafe candidates by the LHD monitor's evidence (model-card figure)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import roc_auc_score

from assurance.fitting.separation import SCORES, auroc, disc_scores, separation
from el.base.decision import Disc
from el.classes.labels import UAVID
from el.monitors.lhd import lhd_rule
from el.monitors.patches import extract_patch


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.integers(0, 5)), min_size=2, max_size=40))
def test_auroc_matches_sklearn_ties_included(pairs) -> None:
    unsafe = np.array([p[0] for p in pairs])
    score = np.array([p[1] for p in pairs], float)  # few distinct values: many ties
    ours = auroc(unsafe, score)
    if unsafe.all() or not unsafe.any():
        assert ours is None
    else:
        assert ours == pytest.approx(roc_auc_score(unsafe, score), abs=1e-12)


def _rows(rng: np.random.Generator, shift: float, scenes: int = 12) -> list[dict]:
    rows = []
    for s in range(scenes):
        for _ in range(int(rng.integers(1, 6))):
            bad = bool(rng.random() < 0.3)
            base = rng.normal(shift if bad else 0.0, 1.0)
            rows.append({"scene": f"s{s}", "unsafe": bad, "max_forbidden_probability": base,
                         "lhd_margin": base - 0.5, "forbidden_fraction": base})
    return rows


def test_separation_interval_brackets_the_point_and_is_deterministic() -> None:
    rows = _rows(np.random.default_rng(0), 2.0)
    a, b = separation(rows, n_boot=200, seed=3), separation(rows, n_boot=200, seed=3)
    assert a == b
    for name in SCORES:
        s = a["scores"][name]
        assert s["ci"][0] <= s["auroc"] <= s["ci"][1]
    assert a["scores"]["max_forbidden_probability"]["auroc"] > 0.8  # a real shift is seen
    unsafe = np.array([r["unsafe"] for r in rows])
    rejected = np.array([r["lhd_margin"] >= 0 for r in rows])
    assert a["lhd_rule"]["recall"] == pytest.approx(rejected[unsafe].mean())
    assert a["lhd_rule"]["fp_rate"] == pytest.approx(rejected[~unsafe].mean())
    assert separation([])["candidates"] == 0


class _Painted:
    """Segments a patch by colour: red pixels road (forbidden), the rest low vegetation."""

    def predict_patch(self, rgb: np.ndarray) -> np.ndarray:
        probs = np.full((8, *rgb.shape[:2]), 0.02, np.float32)
        red = rgb[..., 0] > 128
        probs[2][red] = 0.86   # road
        probs[5][~red] = 0.86  # low vegetation
        return probs


@pytest.mark.parametrize("paint", [False, True])
def test_lhd_margin_is_non_negative_exactly_when_lhd_rejects(paint) -> None:
    rgb = np.zeros((80, 80, 3), np.uint8)
    if paint:
        rgb[40, 41] = (255, 0, 0)
    disc = Disc(40.5, 40.5, 10.0)
    scores = disc_scores(_Painted(), rgb, disc)
    patch = extract_patch(rgb, disc, margin=0.25)
    probs = _Painted().predict_patch(patch.rgb)[:, patch.disc_mask]
    accepted, _ = lhd_rule(probs, labels=UAVID)
    assert (scores["lhd_margin"] >= 0) == (not accepted) == paint
    assert scores["max_forbidden_probability"] == pytest.approx(0.86 if paint else 0.02)
