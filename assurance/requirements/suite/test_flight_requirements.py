"""Requirement tests of the flight code that need no campaign run: no forbidden pixel in a candidate's disc
(EL-R01), the default action when no candidate is validated (EL-R03), candidates in increasing hazard (EL-R05)
and the decision time budget (EL-R07). Shipped with the package so that a report made from an installed wheel
decides them too; the repository's own tests (``tests/``) check the same properties more widely (property-based)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from assurance.campaign.gt_pipeline import decide_from_labels
from el.classes.labels import CLASS_IDS, PALETTE, UAVID, forbidden_mask, ids_to_colors
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.camera import CameraGeometry, working_size
from el.geometry.config import CoreConfig
from el.landing.core import probs_from_labels

W, H, WW = 256, 144, 128


def _scene(seed: int = 0) -> np.ndarray:
    """Low vegetation with a road, a building block and a few trees."""
    rng = np.random.default_rng(seed)
    ids = np.full((H, W), CLASS_IDS["low_vegetation"], np.uint8)
    ids[:, W // 3:W // 3 + 6] = CLASS_IDS["road"]
    ids[:H // 3, 170:202] = CLASS_IDS["building"]
    for _ in range(4):
        y, x = int(rng.integers(H // 3, H - 5)), int(rng.integers(0, W - 5))
        ids[y:y + 4, x:x + 4] = CLASS_IDS["tree"]
    return ids


class _LabelColours:
    """A perfect segmenter of colour-coded label images (colour -> class), at frame and patch level."""

    weights_sha256 = "0f" * 32

    def __init__(self, clock=None, patch_cost_s: float = 0.0) -> None:
        self.clock, self.patch_cost_s = clock, patch_cost_s

    @staticmethod
    def _ids(rgb: np.ndarray) -> np.ndarray:
        d = ((rgb[..., None, :].astype(np.int32) - PALETTE.astype(np.int32)) ** 2).sum(-1)
        return d.argmin(-1).astype(np.uint8)

    def predict_frame(self, rgb: np.ndarray) -> np.ndarray:
        return probs_from_labels(self._ids(rgb), working_size(rgb.shape[1], rgb.shape[0], WW), labels=UAVID)

    def predict_patch(self, rgb: np.ndarray) -> np.ndarray:
        if self.clock is not None:
            self.clock.t += self.patch_cost_s
        return probs_from_labels(self._ids(rgb), (rgb.shape[1], rgb.shape[0]), labels=UAVID)


class _Clock:
    """A clock that advances by ``step`` seconds at each reading."""

    def __init__(self, step: float = 0.0) -> None:
        self.t, self.step = 0.0, step

    def __call__(self) -> float:
        self.t += self.step
        return self.t


def _pipeline(segmenter=None, clock=None, budget: float = 10.0) -> EmergencyLanding:
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", time_budget_s=budget)
    return EmergencyLanding(cfg, segmenter=segmenter or _LabelColours(), **({"clock": clock} if clock else {}))


def _nearest_forbidden_point(ids: np.ndarray, x: float, y: float, r: float) -> float:
    """Distance from (x, y) to the nearest point of a forbidden full-resolution pixel within r + 2 px (inf if none)."""
    forbidden = forbidden_mask(ids)
    x0, x1 = max(int(x - r) - 2, 0), min(int(x + r) + 3, ids.shape[1])
    y0, y1 = max(int(y - r) - 2, 0), min(int(y + r) + 3, ids.shape[0])
    fy, fx = np.nonzero(forbidden[y0:y1, x0:x1])
    if not fy.size:
        return math.inf
    dx = np.maximum(np.abs(fx + x0 + 0.5 - x) - 0.5, 0.0)
    dy = np.maximum(np.abs(fy + y0 + 0.5 - y) - 0.5, 0.0)
    return float(np.sqrt(dx * dx + dy * dy).min())


@pytest.mark.requirements("EL-R01")
@pytest.mark.parametrize("mode", ["exact", "paper"])
def test_no_candidate_disc_holds_a_forbidden_pixel(mode):
    ids = np.full((216, 384), CLASS_IDS["low_vegetation"], np.uint8)
    cv2.line(ids, (0, 60), (383, 215), CLASS_IDS["road"], 1)  # thin diagonal roads: the pooling trap
    cv2.line(ids, (383, 50), (100, 215), CLASS_IDS["road"], 2)
    ids[20:60, 40:90] = CLASS_IDS["building"]
    decision = decide_from_labels(ids, config=CoreConfig(working_width=192, mode=mode), labels=UAVID)
    assert decision.candidates, decision.reason
    first = CameraGeometry(width=384, height=216).first_reachable_row
    for c in decision.candidates:
        assert c.x - c.radius_px >= -1e-9 and c.x + c.radius_px <= 384 + 1e-9, c
        assert c.y - c.radius_px >= -1e-9 and c.y + c.radius_px <= 216 + 1e-9, c
        assert math.floor(c.y) >= first, c
        assert _nearest_forbidden_point(ids, c.x, c.y, c.radius_px) >= c.radius_px - 1e-6, c


@pytest.mark.requirements("EL-R03")
def test_no_valid_ground_gives_the_default_action():
    ids = np.full((H, W), CLASS_IDS["road"], np.uint8)
    assert decide_from_labels(ids, config=CoreConfig(working_width=WW), labels=UAVID).reason == "no_candidate"
    d = _pipeline().decide(ids_to_colors(ids))
    assert (d.action, d.reason, d.selected) == ("default", "no_candidate", None)


@pytest.mark.requirements("EL-R03")
def test_every_candidate_rejected_gives_the_default_action():
    seg = _LabelColours()
    road = np.eye(8, dtype=np.float32)[CLASS_IDS["road"]][:, None, None]
    seg.predict_patch = lambda rgb: road * np.ones((1, *rgb.shape[:2]), np.float32)  # the monitor sees road
    d = _pipeline(seg).decide(ids_to_colors(_scene()))
    assert (d.action, d.reason) == ("default", "all_rejected")
    assert d.candidates and all(c.monitor is not None and not c.monitor.accepted for c in d.candidates)


@pytest.mark.requirements("EL-R05")
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_candidates_are_ranked_by_increasing_hazard(seed):
    decision = decide_from_labels(_scene(seed), config=CoreConfig(working_width=WW), labels=UAVID)
    cands = decision.candidates
    assert len(cands) >= 2
    assert [c.rank for c in cands] == list(range(len(cands)))
    assert [c.hazard for c in cands] == sorted(c.hazard for c in cands)
    for c in cands:
        assert all(0.0 <= v <= 1.0 for v in (c.hazard, c.hazard_semantic, c.hazard_distance))
        assert c.hazard == pytest.approx(0.5 * c.hazard_semantic + 0.5 * c.hazard_distance, abs=1e-12)
    d = _pipeline().decide(ids_to_colors(_scene(seed)))
    walked = [c.rank for c in d.candidates if c.monitor is not None]
    assert walked == list(range(len(walked)))  # the monitor examined them in rank order, from the top


@pytest.mark.requirements("EL-R07")
def test_a_spent_budget_gives_the_default_action():
    d = _pipeline(clock=_Clock(step=100.0), budget=1.0).decide(ids_to_colors(_scene()))
    assert (d.action, d.reason) == ("default", "timeout")


@pytest.mark.requirements("EL-R07")
def test_a_budget_exceeded_while_monitoring_gives_the_default_action():
    clock = _Clock()
    slow = _LabelColours(clock=clock, patch_cost_s=4.0)  # every HD patch costs 4 s on the injected clock
    d = _pipeline(slow, clock=clock, budget=3.0).decide(ids_to_colors(_scene()))
    assert (d.action, d.reason) == ("default", "timeout")
    assert _pipeline(slow, clock=clock, budget=30.0).decide(ids_to_colors(_scene())).action == "land"
