"""Would the out-of-domain gate pay? Its distance on every frame of a campaign, as the campaign saw it.

The gate replayed is a frame gate (``uav-el fit-gate``, ``el.monitors.frame_gate``: the frame pass's own features).

Each (perturbation, severity, image) of the run is re-perturbed with the campaign's own seed
(`assurance.campaign.run.task_seed`), so the gate scores exactly the frames the monitors judged. A frame
above the gate's threshold ends in the default action; `assurance.analysis.sweep` replays the decisions with
those frames forced to default, which says whether sending them to the parachute is safer than what
the monitor decided (it is not when the default area itself is often unsafe).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from assurance.campaign import readouts
from assurance.campaign.task import frame_identity, task_seed
from assurance.dataio.layouts import iter_samples
from assurance.dataio.uavid import read_image
from assurance.perturbations import perturb
from el.monitors.frame_gate import FrameGate, load_frame_gate
from el.segmentation.contract import segment_frame


def load_gate(path: str | Path) -> FrameGate:
    """The frame-gate file at ``path`` (its loader refuses, one line, what it cannot use)."""
    return load_frame_gate(path)


def gate_score(gate: FrameGate, segmenter: Any, rgb: np.ndarray) -> float:
    """The gate's score of one frame, from the statistics its segmentation pass returned."""
    return gate.score(segment_frame(segmenter, rgb, stats=True).stats)


def frame_distances(run: str | Path, data: str | Path, gate_path: str | Path, segmenter: Any,
                    progress: Callable[[int, int], None] | None = None) -> pd.DataFrame:
    """One row per (perturbation, severity, key) of ``run``: the gate's distance and whether it fires."""
    gate = load_gate(gate_path)
    gate.check_network(segmenter)  # a gate fitted on another network than the run's is refused
    man = readouts.read_manifest(run)
    seed = int(man["config"]["seed"])
    images = readouts.load_table(run, "images")
    tasks = images[["perturbation", "severity", "key"]].drop_duplicates().sort_values(["key", "perturbation"])
    samples = {s.key: s for s in iter_samples(data)}
    rows, cache = [], {}
    for i, (pert, sev, key) in enumerate(tasks.itertuples(index=False)):
        if key not in samples:
            raise ValueError(f"{data}: no image {key} (the run was made on other data)")
        if key not in cache:
            cache.clear()
            cache[key] = read_image(samples[key].image_path)
        rng = np.random.default_rng(task_seed(seed, frame_identity(cache[key]), pert, int(sev)))
        d = gate_score(gate, segmenter, perturb(cache[key], pert, int(sev), rng))
        rows.append({"perturbation": pert, "severity": int(sev), "key": key, "ood_distance": d,
                     "ood_fires": bool(d > gate.threshold)})
        if progress:
            progress(i + 1, len(tasks))
    return pd.DataFrame(rows)


def gate_effect(decisions: pd.DataFrame, distances: pd.DataFrame) -> pd.DataFrame:
    """Per perturbation: frames the gate sends to default, and unsafe landings without and with it.

    ``decisions``: one configuration's per-image decisions (``perturbation, severity, key, h_decision,
    h_default``: the run's images table or :func:`assurance.analysis.sweep.replay`)."""
    keys = ["perturbation", "severity", "key"]
    im = decisions.merge(distances, on=keys, how="left")
    fires = im["ood_fires"].astype("boolean").fillna(False).to_numpy(bool)
    im["fires"] = fires
    im["unsafe_without"] = im["h_decision"].to_numpy(float) >= 1.0
    im["unsafe_with"] = np.where(fires, im["h_default"], im["h_decision"]).astype(float) >= 1.0
    g = im.groupby("perturbation", sort=False)
    return pd.DataFrame({
        "frames": g.size(), "gate_fires": g["fires"].sum(),
        "unsafe_without_gate": g["unsafe_without"].sum(), "unsafe_with_gate": g["unsafe_with"].sum(),
    }).reset_index()
