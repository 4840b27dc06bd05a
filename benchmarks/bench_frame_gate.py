"""Decision time with a frame gate vs without (issue 32): target at most 10% above.

The gate reads the frame pass's own statistics (``Segmenter.tap_frames``: the ONNX export's trunk outputs from
the same pass as the logits, pooled; ``el/segmentation/frame_tap.py``) and scores them (``el.monitors.gates``,
Mahalanobis by default, fitted on ``--train`` frames before timing). Each frame is decided with and without,
interleaved (A/B), by ``EmergencyLanding.decide`` with the deployed monitor on the image array; median and mean
over the frames.

    .venv/bin/python benchmarks/bench_frame_gate.py --data data/gate/val --train data/gate/train [--frames 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from assurance.scenes.uavid import iter_samples, read_image
from el.monitors.gates import GATES
from el.pipeline import EmergencyLanding, PipelineConfig
from el.segmentation.factory import load_model


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/gate/val", help="frames to decide on")
    p.add_argument("--train", default="data/gate/train", help="frames to fit the gate on (not timed)")
    p.add_argument("--frames", type=int, default=10)
    p.add_argument("--gate", default="mahalanobis", choices=sorted(GATES))
    args = p.parse_args(argv)
    seg = load_model(None, working_width=1024)
    gate = GATES[args.gate]
    seg.tap_frames = True
    fit = []
    for s in list(iter_samples(args.train, require_labels=False))[:20]:
        seg.predict_frame(read_image(s.image_path))
        fit.append(gate.embed(seg.last_tap))
    params = gate.fit(np.array(fit))
    system = EmergencyLanding(PipelineConfig(time_budget_s=None), segmenter=seg)
    frames = [read_image(s.image_path) for s in list(iter_samples(args.data, require_labels=False))[:args.frames]]
    system.decide(frames[0])  # warm-up
    times: dict[str, list[float]] = {"without": [], "with": []}
    for rgb in frames:
        for mode in ("without", "with"):
            seg.tap_frames = mode == "with"
            t = time.perf_counter()
            system.decide(rgb)
            if mode == "with":
                gate.score(params, gate.embed(seg.last_tap)[None])
            times[mode].append(time.perf_counter() - t)
    med = {k: statistics.median(v) for k, v in times.items()}
    mean = {k: statistics.fmean(v) for k, v in times.items()}
    for k in times:
        print(f"{k:8s} gate ({args.gate}): median {med[k] * 1000:.0f} ms, mean {mean[k] * 1000:.0f} ms "
              f"over {len(frames)} frames of {frames[0].shape[1]}x{frames[0].shape[0]}")
    ratio = med["with"] / med["without"]
    print(f"with / without: {ratio:.3f} (median), {mean['with'] / mean['without']:.3f} (mean); target <= 1.10")
    return 0 if ratio <= 1.10 else 1


if __name__ == "__main__":
    sys.exit(main())
