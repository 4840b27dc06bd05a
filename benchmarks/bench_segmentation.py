"""Segmentation latency and memory: frames, HD patches, MC dropout (one batch vs separate passes).

Usage::

    .venv/bin/python benchmarks/bench_segmentation.py [--weights PATH] [--repeats 10] [--threads 2] [--json OUT]

Uses the shipped weights when present (el/segmentation/weights/model.pt), else a seeded, randomly
initialised network of the default architecture (the table says which: timings do not depend on the
weights' values). Timings interleave the cases round by round in one process (noise from other jobs on a shared CPU
hits every case alike); peak memory is measured per case in a fresh process (resident-set
high-water mark above the resident size before the call). Targets on the 2-core CPU:
working-resolution frame (as deployed) < 0.5 s median; MC dropout n = 10 < 3x one HD patch forward.
"""

from __future__ import annotations

import argparse
import copy
import importlib.util
import json
import multiprocessing as mp
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

CASES = (
    ("frame 1024x576", "frame", 576, 1024, 0),  # as deployed: the card's frame_flip and frame_scales
    ("frame 1024x576, frame alone", "frame_plain", 576, 1024, 0),
    ("frame 1024x576, + mirror image", "frame_flip", 576, 1024, 0),
    ("frame 1024x576, fed at x1.25", "frame_x1.25", 576, 1024, 0),
    ("frame 1024x576, fed at x1, x1.25", "frame_x1+1.25", 576, 1024, 0),
    ("frame 3840x2160 (incl. resize)", "frame", 2160, 3840, 0),
    ("HD patch 384x384", "patch", 384, 384, 0),
    ("MC dropout n=10, one batch", "mc", 384, 384, 10),
    ("MC dropout n=10, 10 passes", "mc_loop", 384, 384, 10),
    ("MC dropout n=30, one batch", "mc", 384, 384, 30),
    ("MC dropout n=30, 30 passes", "mc_loop", 384, 384, 30),
)
# Frame cases forced to one way of segmenting, whatever the card says (Segmenter keywords).
FRAME_VARIANTS = {
    "frame_plain": {"frame_flip": False, "frame_scales": (1.0,)},
    "frame_flip": {"frame_flip": True, "frame_scales": (1.0,)},
    "frame_x1.25": {"frame_flip": False, "frame_scales": (1.25,)},
    "frame_x1+1.25": {"frame_flip": False, "frame_scales": (1.0, 1.25)},
}


def _current_rss_kb() -> int:
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * resource.getpagesize() // 1024


def _setup(weights: str | None, threads: int):
    import torch

    from assurance.fitting.network.training import init_untrained
    from el.classes.labels import UAVID
    from el.segmentation.inference import Segmenter

    torch.set_num_threads(threads)  # the shipped architecture, untrained: UAVid's classes
    return Segmenter.load(weights) if weights else Segmenter(init_untrained(seed=0), labels=UAVID)


def _runner(seg, kind: str, h: int, w: int, n: int):
    rgb = np.random.default_rng(0).integers(0, 256, (h, w, 3), dtype=np.uint8)
    if kind == "frame":
        return lambda: seg.predict_frame(rgb)
    if kind in FRAME_VARIANTS:
        variant = copy.copy(seg)
        variant.__dict__.update(FRAME_VARIANTS[kind])
        return lambda: variant.predict_frame(rgb)
    if kind == "patch":
        return lambda: seg.predict_patch(rgb)
    if kind == "mc":
        return lambda: seg.mc_dropout(rgb, n, 0.75, 0)
    return lambda: [seg.mc_dropout(rgb, 1, 0.75, i) for i in range(n)]


def _peak_memory(args: tuple) -> float:
    """Peak resident memory (MB) of one call of a case above the process's size before it."""
    kind, h, w, n, weights, threads = args
    fn = _runner(_setup(weights, threads), kind, h, w, n)
    rss0 = _current_rss_kb()
    fn()
    return max(0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024


def _timings(weights: str | None, threads: int, repeats: int) -> dict[str, list[float]]:
    """Wall times per case, the cases interleaved round by round (shared-CPU noise hits all alike)."""
    seg = _setup(weights, threads)
    fns = {name: _runner(seg, kind, h, w, n) for name, kind, h, w, n in CASES}
    for fn in fns.values():
        fn()  # warm-up
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--weights", type=Path, help="weights file (default: shipped if present, else random)")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--json", type=Path, help="also write the results as JSON")
    args = parser.parse_args(argv)

    # The shipped weights' path, found without importing torch: the memory cases run in fresh
    # processes, which inherit this process's resident-set high-water mark, so it must stay small.
    spec = importlib.util.find_spec("el.segmentation")
    shipped = Path(spec.submodule_search_locations[0]) / "weights" / "model.pt"
    weights = args.weights or (shipped if shipped.exists() else None)
    source = f"weights {weights}" if weights else "randomly initialised weights (no shipped weights found)"
    print(f"segmentation benchmark: {source}; {args.threads} threads, {args.repeats} repeats per case")
    print("'frame 1024x576' runs as the card says (frame_flip, frame_scales); the next four rows force a way")
    ctx = mp.get_context("spawn")
    wname = str(weights) if weights else None
    peaks = {}
    for name, kind, h, w, n in CASES:  # first, while this process is small (see above)
        with ctx.Pool(1) as pool:  # a fresh process per case: its own memory high-water mark
            peaks[name] = pool.apply(_peak_memory, ((kind, h, w, n, wname, args.threads),))
    times = _timings(wname, args.threads, args.repeats)
    rows = [{"case": name, "median_s": statistics.median(times[name]),
             "p95_s": float(np.percentile(times[name], 95)), "peak_mb": peaks[name]} for name, *_ in CASES]
    print(f"\n| {'case':<34} | {'median s':>9} | {'p95 s':>8} | {'peak MB':>8} |")
    print(f"|{'-' * 36}|{'-' * 11}|{'-' * 10}|{'-' * 10}|")
    for r in rows:
        print(f"| {r['case']:<34} | {r['median_s']:>9.3f} | {r['p95_s']:>8.3f} | {r['peak_mb']:>8.1f} |")
    by = {r["case"]: r for r in rows}
    frame = by["frame 1024x576"]["median_s"]
    patch = by["HD patch 384x384"]["median_s"]
    mc10 = by["MC dropout n=10, one batch"]["median_s"]
    checks = [
        (f"frame 1024x576 median {frame:.3f} s < 0.5 s", frame < 0.5),
        (f"MC n=10 one batch {mc10:.3f} s = {mc10 / patch:.1f}x one patch forward (< 3x)", mc10 < 3 * patch),
    ]
    print()
    for text, ok in checks:
        print(f"{'PASS' if ok else 'FAIL'}  {text}")
    if args.json:
        args.json.write_text(json.dumps({"weights": str(weights) if weights else None, "threads": args.threads,
                                         "rows": rows, "checks": [{"check": t, "ok": ok} for t, ok in checks]},
                                        indent=2))
    return 0 if all(ok for _, ok in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
