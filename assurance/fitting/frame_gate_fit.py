"""Fitting the deployed frame gate (``el.monitors.frame_gate``, ``uav-el fit-gate``): one candidate of
``el.monitors.gates`` fitted on the training scenes with the in-domain perturbations applied (each scene clean,
under each perturbation at a severity drawn from 1-3, and at severity 3), thresholded at a stated quantile of
validation scenes under each perturbation at severity 3 (``assurance.fitting.gate_frames``: the study's frames).
The in-domain perturbations are the shipped gate's six, or those a system file declares
(``assurance.campaign.perturbation_plan.fit_levels``), each at most at its declared maximum.

Any network that returns its frame pass's statistics can be fitted (``el.monitors.frame_gate.returns_frame_stats``:
the shipped ``Segmenter``, an ONNX file, either behind a class map). A Mahalanobis or kNN gate reads the trunk's pooled
statistics where the network gives them (``features="pooled"``), else the pooled statistics of its output, which
every network has (``"output"``); ``features`` chooses.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from assurance.dataio.layouts import iter_samples, located
from assurance.fitting.gate_frames import in_domain, scene_images, training_frames, validation_frames
from assurance.fitting.learned_monitor import split_sha256
from assurance.paths import shown_path
from assurance.progress import progress as bar
from el.monitors.frame_gate import check_frame_stats, frame_gate_document
from el.monitors.gates import GATES, WHAT
from el.segmentation.contract import segment_frame

# the shipped gate's: the smallest meeting the policy in both validation folds (docs/results.md)
DEFAULT_QUANTILE = 0.997
FEATURES = WHAT  # what each tap feature is, recorded in the file
CHOICES = ("auto", "trunk", "output")
"""``uav-el fit-gate --features``: ``auto`` (the trunk's statistics where the network gives them, else its
output's), ``trunk`` or ``output``."""


def parse_scenes(text: str | None) -> tuple[int, int | None]:
    """``FIRST:END`` (0-based, END excluded; either may be empty) -> (first, count or None)."""
    if not text:
        return 0, None
    try:
        first_s, end_s = text.split(":")
        first = int(first_s) if first_s else 0
        end = int(end_s) if end_s else None
    except ValueError:
        raise ValueError(f"scenes must be FIRST:END (e.g. 0:35), got {text!r}") from None
    if first < 0 or (end is not None and end <= first):
        raise ValueError(f"scenes {text!r}: need 0 <= FIRST < END")
    return first, None if end is None else end - first


def tap_of(segmenter: Any, rgb: np.ndarray) -> Any:
    """The frame pass's statistics of ``rgb`` (``FrameTap``); ValueError when the network returned none."""
    tap = segment_frame(segmenter, rgb, stats=True).stats
    if tap is None:
        raise ValueError(f"the segmentation model {type(segmenter).__name__} segmented a frame but returned no frame "
                         "statistics (predict_frame(rgb, stats=True)): a frame gate cannot be fitted on it")
    return tap


def gate_features(kind: str, choice: str, tap: Any) -> str:
    """The tap features a gate of ``kind`` reads for ``choice`` (:data:`CHOICES`), given a frame's ``tap``."""
    if choice not in CHOICES:
        raise ValueError(f"features must be one of {', '.join(CHOICES)}, got {choice!r}")
    readable = GATES[kind].FEATURES
    if readable == ("energy",):
        return "energy"  # the energy gate reads the logits whatever is asked
    if choice == "trunk":
        if tap.pooled is None:
            raise ValueError("--features trunk: the network's frame pass gives no trunk features (an ONNX file "
                             "without trunk outputs, or a network without a trunk); use --features output")
        return "pooled"
    if choice == "output":
        return "output"
    return "pooled" if tap.pooled is not None else "output"


def embed(gate: Any, segmenter: Any, frames: Iterable[tuple[int, str, np.ndarray]], total: int, desc: str,
          progress: bool, features: str | None = None) -> np.ndarray:
    """The gate's features (n, d) of ``frames``, each read from the frame pass's own tap (``features``: which;
    None: the gate's default)."""
    check_frame_stats(segmenter, "frame gate")
    which = features or gate.FEATURES[0]
    rows = []
    for _, _, rgb in bar(frames, total=total, desc=desc, enabled=progress):
        rows.append(np.asarray(gate.embed(tap_of(segmenter, rgb), which), np.float64))
    x = np.asarray(rows, np.float64)
    if x.ndim != 2 or not np.isfinite(x).all():
        raise ValueError(f"{desc}: non-finite frame features")
    return x


def _split(path: str | Path, first: int, count: int | None) -> dict[str, Any]:
    """A split's record: as shown (``path``), where it is and how it was read (``spec``: the absolute root and the
    table's layout, split list, ...: the evidence report finds the frames there again), the scenes used, their hash."""
    samples = list(iter_samples(path, require_labels=False))[first:None if count is None else first + count]
    return {"path": shown_path(path), "spec": located(path),
            "scenes": [first, first + len(samples)], "sha256": split_sha256(samples, path, labels=False)}


def _named(domain: Sequence[tuple[str, int]]) -> str:
    """The perturbations a gate is fitted under, as its file records them (``none`` aside)."""
    return ", ".join(name for name, _ in domain[1:]) or "no perturbation"


def _capped(domain: Sequence[tuple[str, int]]) -> str:
    """What the record adds when a declared maximum below 3 capped a perturbation's severity."""
    low = [f"{name} {top}" for name, top in domain[1:] if top < 3]
    return f" (at most the declared maximum: {', '.join(low)})" if low else ""


@dataclass(frozen=True, kw_only=True)
class GateSettings:
    """What gate :func:`fit_gate` fits: its ``kind`` (``el.monitors.gates.GATES``), the ``quantile`` of the validation
    frames' scores its threshold is, the ``features`` it reads (:data:`CHOICES`: what the Mahalanobis and kNN gates
    read), and the in-domain ``perturbations`` as (name, top severity) (a system's declared ones,
    ``assurance.campaign.perturbation_plan.fit_levels``; None: the shipped gate's six). Kind and quantile are
    checked when built."""

    kind: str = "mahalanobis"
    quantile: float = DEFAULT_QUANTILE
    features: str = "auto"
    perturbations: Sequence[tuple[str, int]] | None = None

    def __post_init__(self) -> None:
        if self.kind not in GATES:
            raise ValueError(f"unknown gate kind {self.kind!r}; known: {', '.join(sorted(GATES))}")
        if not 0.0 < self.quantile < 1.0:
            raise ValueError(f"quantile must lie in (0, 1), got {self.quantile!r}")


def fit_gate(data: str | Path, val: str | Path, segmenter: Any, *, settings: GateSettings | None = None,
             train_scenes: str | None = None, val_scenes: str | None = None, weights: dict[str, Any],
             progress: bool = False) -> dict[str, Any]:
    """The gate document: fitted on ``data``, thresholded on ``val`` as ``settings`` say (:class:`GateSettings`;
    None: its defaults) (``uav-el fit-gate``); ``train_scenes``, ``val_scenes``: which scenes of each
    (:func:`parse_scenes`). ValueError (one line) for a network that keeps no frame statistics."""
    settings = settings or GateSettings()
    kind, quantile = settings.kind, settings.quantile
    features, perturbations = settings.features, settings.perturbations
    gate = GATES[kind]
    t_first, t_count = parse_scenes(train_scenes)
    v_first, v_count = parse_scenes(val_scenes)
    train_paths, val_paths = scene_images(data, t_first, t_count), scene_images(val, v_first, v_count)
    if len(train_paths) < 2 or not val_paths:
        raise ValueError(f"{len(train_paths)} training scene(s) in {data} and {len(val_paths)} validation scene(s) "
                         f"in {val}: need >= 2 and >= 1")
    domain = in_domain(perturbations)
    n = len(domain)
    check_frame_stats(segmenter, "frame gate")
    tap = gate_features(kind, features, tap_of(segmenter, next(training_frames(train_paths[:1]))[2]))
    train = embed(gate, segmenter, training_frames(train_paths, levels=perturbations),
                  (2 * n - 1) * len(train_paths), "training frames", progress, tap)
    held = embed(gate, segmenter, validation_frames(list(enumerate(val_paths, v_first)), (3,), levels=perturbations),
                 n * len(val_paths), "validation frames", progress, tap)
    params = gate.fit(train)
    scores = gate.score(params, held)
    body = {"kind": kind, "features": {"tap": tap, "what": FEATURES[tap], "dims": int(train.shape[1])},
            "params": params, "threshold": float(np.quantile(scores, quantile)), "quantile": float(quantile),
            "training": {**_split(data, t_first, t_count), "frames": int(train.shape[0]),
                         "perturbations": "each scene clean, under each of " + _named(domain)
                                          + " at a severity drawn from 1-3 (seeded per scene) and at severity 3"
                                          + _capped(domain)},
            "validation": {**_split(val, v_first, v_count), "frames": int(held.shape[0]),
                           "perturbations": "each scene clean and under each of " + _named(domain)
                                            + " at severity 3" + _capped(domain),
                           "median": float(np.median(scores)), "max": float(scores.max())},
            "weights": weights, "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")}
    return frame_gate_document(body)
