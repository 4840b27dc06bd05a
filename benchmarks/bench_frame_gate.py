"""Decision time with the frame gate deployed vs without (issue 32): target at most 10% above.

Two systems with the deployed monitor, each on its own copy of the shipped network: one with
``PipelineConfig(gate=GATE.json)`` (the frame pass keeps its statistics, ``Segmenter.tap_frames``; the gate scores
them, ``el.monitors.frame_gate``), one without. Each frame is decided by both, interleaved (A/B), by
``EmergencyLanding.decide`` on the image array; median and mean over the frames.

    .venv/bin/python benchmarks/bench_frame_gate.py --gate runs/gates/frame_gate.json --data data/gate/val [--frames 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from assurance.scenes.uavid import iter_samples, read_image
from el.pipeline import EmergencyLanding, PipelineConfig
from el.segmentation.factory import load_model


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--gate", required=True, help="frame-gate file (uav-el fit-gate) for the shipped network")
    p.add_argument("--data", default="data/gate/val", help="frames to decide on")
    p.add_argument("--frames", type=int, default=10)
    args = p.parse_args(argv)
    systems = {mode: EmergencyLanding(PipelineConfig(time_budget_s=None, gate=args.gate if mode == "with" else None),
                                      segmenter=load_model(None, working_width=1024))
               for mode in ("without", "with")}
    if systems["with"].fault:
        print(f"the gated system is faulted: {systems['with'].fault}", file=sys.stderr)
        return 2
    frames = [read_image(s.image_path) for s in list(iter_samples(args.data, require_labels=False))[:args.frames]]
    for system in systems.values():
        system.decide(frames[0])  # warm-up
    times: dict[str, list[float]] = {"without": [], "with": []}
    gated = 0
    for rgb in frames:
        for mode, system in systems.items():
            t = time.perf_counter()
            d = system.decide(rgb)
            times[mode].append(time.perf_counter() - t)
            gated += mode == "with" and d.input["frame_gate"]["score"] is not None
    med = {k: statistics.median(v) for k, v in times.items()}
    mean = {k: statistics.fmean(v) for k, v in times.items()}
    for k in times:
        print(f"{k:8s} gate: median {med[k] * 1000:.0f} ms, mean {mean[k] * 1000:.0f} ms over {len(frames)} frames "
              f"of {frames[0].shape[1]}x{frames[0].shape[0]}")
    ratio = med["with"] / med["without"]
    print(f"{gated} of {len(frames)} gated decisions scored; with / without: {ratio:.3f} (median), "
          f"{mean['with'] / mean['without']:.3f} (mean); target <= 1.10")
    return 0 if ratio <= 1.10 and gated == len(frames) else 1


if __name__ == "__main__":
    sys.exit(main())
