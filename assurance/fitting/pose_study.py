"""Metric evidence for the safety radius and beta (EL-R02): render with a perturbed pose, plan with the nominal one.

For each scene and each pose error (height and pitch each off by up to +-20%), the scene's world is
rendered with the *true* pose, the ground-truth pipeline plans on the label map with the *nominal*
pose (50 m, 45 deg), and every candidate's landing point (where its centre pixel's ray meets the
ground under the true pose) gets its true metric clearance to the nearest road, car or building
footprint of the world model, hidden parts included. The requirement: clearance >= R (2 m by default).

A violation can come from the geometry (beta too small) or from what the labels cannot show: a road
hidden under a tree canopy is labelled "tree" in the image, so no planner that trusts the image can
keep clear of it. Each violation gets a ``cause``: "hidden" when every part of the nearest
footprint within reach is labelled safe in the image (e.g. under a canopy), "out_of_view" when it
lies outside the frame, else "geometry" (what beta must absorb: EL-R02 accepts none of those).

Run ``python -m assurance.fitting.pose_study --scenes 10`` for the table of the evidence.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from assurance.campaign.gt_pipeline import decide_from_labels
from assurance.scenes.generate import default_geometry, generate_world, scene_seed
from assurance.scenes.renderer import render
from assurance.scenes.world import World, pixel_clearance_m
from el.classes.labels import FORBIDDEN_LUT, UAVID
from el.geometry.camera import Pose, SafetyParams
from el.geometry.config import CoreConfig

POSE_ERRORS = (-0.2, 0.0, 0.2)


@dataclass(frozen=True)
class PoseCase:
    height_error: float
    pitch_error: float

    def pose(self, nominal: Pose) -> Pose:
        return Pose(height_m=nominal.height_m * (1 + self.height_error),
                    pitch_deg=nominal.pitch_deg * (1 + self.pitch_error))

    @property
    def label(self) -> str:
        return f"h{self.height_error:+.0%} p{self.pitch_error:+.0%}"


def pose_cases(errors: Sequence[float] = POSE_ERRORS) -> list[PoseCase]:
    """The corners and centre of the error box (every combination of the given relative errors)."""
    return [PoseCase(h, p) for h, p in itertools.product(errors, errors)]


def candidate_clearances(seeds: Iterable[int], *, size: tuple[int, int] = (1920, 1080),
                         modes: Sequence[str] = ("exact", "paper"),
                         cases: Sequence[PoseCase] | None = None, split: str = "val",
                         working_width: int = 1024, safety: SafetyParams | None = None) -> pd.DataFrame:
    """One row per (scene, mode, pose case, candidate): its true clearance in metres.

    ``safety``: the R and beta the planner uses and the clearance is judged against (default ``SafetyParams()``,
    the flight code's; EL-R02's test passes the registry's targets ``radius_m`` and ``beta``).
    """
    safety = safety or SafetyParams()
    radius_m = safety.radius_m
    cases = list(cases or pose_cases())
    nominal = Pose()
    rows = []
    for index in seeds:
        seed = scene_seed(split, index)
        world = generate_world(seed, split=split, geometry=default_geometry(size))
        for case in cases:
            geo = default_geometry(size, case.pose(nominal))
            labels = render(world, geo).labels
            for mode in modes:
                cfg = CoreConfig(mode=mode, working_width=working_width, safety=safety)  # the nominal pose
                d = decide_from_labels(labels, config=cfg, labels=UAVID)
                if not d.candidates:
                    rows.append({"seed": seed, "mode": mode, "case": case.label, "candidate": -1,
                                 "clearance_m": np.nan, "cause": ""})
                    continue
                xs = np.array([c.x for c in d.candidates]) - 0.5
                ys = np.array([c.y for c in d.candidates]) - 0.5
                clear = pixel_clearance_m(world, geo, xs, ys)
                for k, c in enumerate(clear):
                    cause = violation_cause(world, geo, labels, xs[k], ys[k], float(c)) if c < radius_m else ""
                    rows.append({"seed": seed, "mode": mode, "case": case.label, "candidate": k,
                                 "clearance_m": float(c), "cause": cause})
    return pd.DataFrame(rows)


def violation_cause(world: World, geometry, labels: np.ndarray, col: float, row: float, clearance: float) -> str:
    """Why a landing point at pixel (col, row) is closer than R to a footprint (see the module doc)."""
    gx, gy = geometry.pixel_to_ground(np.array([col]), np.array([row]))
    angles = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    r = clearance + 0.05
    px, py = gx[0] + r * np.cos(angles), gy[0] + r * np.sin(angles)
    inside = world.clearance_m(px, py) <= 1e-6
    if not inside.any():
        return "geometry"
    u, v = geometry.ground_to_pixel(px[inside], py[inside])
    h, w = labels.shape
    iu, iv = np.round(u).astype(int), np.round(v).astype(int)
    in_view = (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
    if not in_view.any():
        return "out_of_view"
    if FORBIDDEN_LUT[labels[iv[in_view], iu[in_view]]].any():
        return "geometry"
    return "hidden"


def summarise(df: pd.DataFrame, radius_m: float = 2.0) -> pd.DataFrame:
    """mode x pose case -> candidates, minimum clearance, violations below R by cause."""
    cands = df[df["candidate"] >= 0]
    g = cands.groupby(["mode", "case"], sort=False)
    out = g["clearance_m"].agg(candidates="count", min_clearance_m="min",
                               below_R=lambda s: int((s < radius_m).sum())).reset_index()
    for cause in ("geometry", "hidden", "out_of_view"):
        out[cause] = g["cause"].agg(lambda s, c=cause: int((s == c).sum())).to_numpy()
    out["share_below_R"] = out["below_R"] / out["candidates"].where(out["candidates"] > 0)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(description="Metric clearance of candidates under pose errors (EL-R02 evidence).")
    p.add_argument("--scenes", type=int, default=10, help="validation-split scenes (default 10)")
    p.add_argument("--size", default="1920x1080", help="render size WxH (default 1920x1080)")
    p.add_argument("--csv", help="also write the per-candidate rows here")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    df = candidate_clearances(range(args.scenes), size=(w, h))
    if args.csv:
        df.to_csv(args.csv, index=False)
    print(summarise(df).to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
