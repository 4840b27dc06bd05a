"""Decision time with the frame gate deployed vs without: target at most 10% above.

Two systems with the deployed monitor, each on its own copy of the shipped network: one with
``PipelineConfig(gate=GATE.json)`` (the frame pass returns its statistics with its probabilities,
``predict_frame(rgb, stats=True)``; the gate scores them, ``el.monitors.frame_gate``), one without. Each frame is
decided by both, interleaved (A/B), by ``EmergencyLanding.decide`` on the image array; median and mean over the
frames. By default: the deployed gate (``el.flight.pipeline.DEPLOYED_GATE``) on synthetic validation scenes at the
camera's
3840x2160, made in a temporary folder.

    .venv/bin/python benchmarks/bench_frame_gate.py [--gate GATE.json] [--data data/gate4k/val] [--frames 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from assurance.dataio.uavid import iter_samples, read_image
from el.flight.pipeline import DEPLOYED_GATE, EmergencyLanding, PipelineConfig
from el.segmentation.factory import load_model

SHIPPED_GATE = Path(__file__).resolve().parents[1] / "el" / "monitors" / "data" / "frame_gate.json"


def _frames(data: str | None, n: int, tmp: str) -> list:
    """The first ``n`` frames of ``data``, or of ``n`` synthetic validation scenes at 3840x2160 written to ``tmp``."""
    if data is None:
        from assurance.scenes.generate import write_dataset

        write_dataset(tmp, n, 0, "val", (3840, 2160), progress=False)
        data = tmp
    return [read_image(s.image_path) for s in list(iter_samples(data, require_labels=False))[:n]]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--gate", default=str(DEPLOYED_GATE or SHIPPED_GATE),
                   help="frame-gate file (uav-el fit-gate) for the shipped network (default: the deployed one)")
    p.add_argument("--data", help="frames to decide on (default: synthetic 3840x2160 validation scenes)")
    p.add_argument("--frames", type=int, default=10)
    args = p.parse_args(argv)
    systems = {mode: EmergencyLanding(PipelineConfig(time_budget_s=None, gate=args.gate if mode == "with" else None),
                                      segmenter=load_model(None, working_width=1024))
               for mode in ("without", "with")}
    if systems["with"].fault:
        print(f"the gated system is faulted: {systems['with'].fault}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="uav-el-bench-gate-") as tmp:
        frames = _frames(args.data, args.frames, tmp)
    if not frames:
        print(f"{args.data}: no scenes (generate them with `uav-el synth`)", file=sys.stderr)
        return 2
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
    print(f"| {len(frames)} frames of {frames[0].shape[1]}x{frames[0].shape[0]} | median ms | mean ms |")
    print("|---|---|---|")
    for k in times:
        print(f"| {k} gate | {med[k] * 1000:.0f} | {mean[k] * 1000:.0f} |")
    ratio = med["with"] / med["without"]
    print(f"{gated} of {len(frames)} gated decisions scored; with / without: {ratio:.3f} (median), "
          f"{mean['with'] / mean['without']:.3f} (mean); target <= 1.10")
    return 0 if ratio <= 1.10 and gated == len(frames) else 1


if __name__ == "__main__":
    sys.exit(main())
