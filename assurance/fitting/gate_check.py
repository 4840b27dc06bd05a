"""Checking a fitted frame gate (``uav-el fit-gate``) on other scenes: each scene clean and under each in-domain
perturbation at severity 3 (the study's validation frames, ``assurance.fitting.gate_frames``), scored from the
frame pass's own tap; the share flagged per perturbation. Used to check the gate at another frame size than it was
fitted on (docs/results.md, "How the frame gate was chosen": fitted on 1024x576 renders, it flags most
3840x2160 frames).

Run: ``python -m assurance.fitting.gate_check GATE.json DATA [--working-width 1024]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from assurance.fitting.gate_frames import scene_images, validation_frames
from el.monitors.frame_gate import bind_frame_gate, load_frame_gate
from el.segmentation.contract import segment_frame
from el.segmentation.factory import load_model


def check(gate_path: str | Path, data: str | Path, segmenter: Any) -> dict[str, dict[str, float]]:
    """Per perturbation (``name:severity``): frames, flagged, median and max score."""
    gate = load_frame_gate(gate_path)
    bind_frame_gate(gate, segmenter)  # fitted on this network, which returns frame statistics
    scores: dict[str, list[float]] = {}
    for _, what, rgb in validation_frames(list(enumerate(scene_images(Path(data)))), (3,)):
        scores.setdefault(what, []).append(gate.score(segment_frame(segmenter, rgb, stats=True).stats))
    return {w: {"frames": len(v), "flagged": int((np.array(v) > gate.threshold).sum()),
                "median": float(np.median(v)), "max": float(np.max(v))} for w, v in scores.items()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("gate")
    p.add_argument("data")
    p.add_argument("--working-width", type=int, default=1024)
    args = p.parse_args(argv)
    result = check(args.gate, args.data, load_model(None, working_width=args.working_width))
    threshold = load_frame_gate(args.gate).threshold
    print(f"| frames of {args.data} | frames | flagged (> {threshold:.4g}) | median score | max score |")
    print("|---|---|---|---|---|")
    for w, r in result.items():
        print(f"| {w} | {r['frames']} | {r['flagged']} | {r['median']:.2f} | {r['max']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
