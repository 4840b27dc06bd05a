"""Decision latency of the shipped network under torch and under ONNX Runtime, on the same 3840x2160 PNGs.

For each engine (``UAV_EL_ENGINE=torch`` / ``onnx``, chosen by :func:`el.segmentation.onnx_engine.engine_for`)
and each configuration, ``el.pipeline.EmergencyLanding.decide`` on the file path (read, segment, candidates,
monitor walk), median and p95 over the frames; the engines are interleaved frame by frame (and the whole
measure repeated ``--rounds`` times) so that other load on the shared CPU hits both alike. Also counts the
frames whose decision (action, selected candidate, candidate positions) differs between the engines.
Target on 2 cores (issue 29): deployed decision on a 3840x2160 PNG < 0.35 s median.

    .venv/bin/python benchmarks/bench_engines.py [--data data/test] [--scenes 10] [--threads 2] [--rounds 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

from assurance.scenes.uavid import iter_samples
from el.pipeline import DEPLOYED_MONITOR, EmergencyLanding, PipelineConfig
from el.segmentation.factory import load_model
from el.segmentation.onnx_engine import ENGINE_ENV

CONFIGS = {"none": "CM only", "lhd": "CM + LHD", DEPLOYED_MONITOR: "deployed (learned, score walk)"}
ENGINES = ("torch", "onnx")
TARGET_S = 0.35


def _load(engine: str, threads: int) -> object:
    old = os.environ.get(ENGINE_ENV)
    os.environ[ENGINE_ENV] = engine
    try:
        seg = load_model(None, threads=threads)
    finally:
        if old is None:
            del os.environ[ENGINE_ENV]
        else:
            os.environ[ENGINE_ENV] = old
    if getattr(seg, "engine_name", None) != engine:
        raise SystemExit(f"engine {engine} not available (install onnxruntime; el/segmentation/weights/model.onnx)")
    return seg


def _key(d: object) -> tuple:
    return (d.action, d.selected, tuple((round(c.x, 3), round(c.y, 3)) for c in d.candidates))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/test", help="UAVid-layout scenes (default data/test)")
    p.add_argument("--scenes", type=int, default=10, help="frames to decide on (default 10)")
    p.add_argument("--threads", type=int, default=2, help="threads of either engine (default 2)")
    p.add_argument("--rounds", type=int, default=2, help="repeat the interleaved measure (default 2)")
    args = p.parse_args(argv)
    samples = list(iter_samples(args.data))[: args.scenes]
    if not samples:
        print(f"{args.data}: no scenes (generate them with `uav-el synth`)", file=sys.stderr)
        return 2
    segs = {e: _load(e, args.threads) for e in ENGINES}
    systems = {(e, spec): EmergencyLanding(PipelineConfig(monitor=spec, time_budget_s=None), segmenter=segs[e])
               for e in ENGINES for spec in CONFIGS}
    for system in systems.values():  # warm up: first-call allocations, ONNX Runtime's arena
        system.decide(samples[0].image_path)
    lat: dict[tuple[str, str], list[float]] = {k: [] for k in systems}
    seg_s: dict[tuple[str, str], list[float]] = {k: [] for k in systems}
    differ = dict.fromkeys(CONFIGS, 0)
    for r in range(args.rounds):
        for s in samples:
            for spec in CONFIGS:
                keys = {}
                for e in (ENGINES if r % 2 == 0 else ENGINES[::-1]):
                    t = time.perf_counter()
                    d = systems[(e, spec)].decide(s.image_path)
                    lat[(e, spec)].append(time.perf_counter() - t)
                    seg_s[(e, spec)].append(d.timings.get("segmentation_s", float("nan")))
                    if d.reason.startswith("fault"):
                        print(f"{s.key} {e} {spec}: {d.reason}", file=sys.stderr)
                    keys[e] = _key(d)
                differ[spec] += r == 0 and keys["torch"] != keys["onnx"]
    print(f"decision latency, {len(samples)} frames of {args.data} x {args.rounds} rounds, {args.threads} threads, "
          "engines interleaved\n")
    print("| configuration | engine | median s | p95 s | segmentation median s | decisions differing |")
    print("|---|---|---|---|---|---|")
    for spec, name in CONFIGS.items():
        for e in ENGINES:
            v = lat[(e, spec)]
            print(f"| {name} | {e} | {statistics.median(v):.3f} | {float(np.percentile(v, 95)):.3f} | "
                  f"{statistics.median(seg_s[(e, spec)]):.3f} | {differ[spec] if e == 'onnx' else '-'} |")
    deployed = statistics.median(lat[("onnx", DEPLOYED_MONITOR)])
    print(f"\n{'PASS' if deployed < TARGET_S else 'FAIL'}  deployed decision under ONNX Runtime, median "
          f"{deployed:.3f} s < {TARGET_S} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
