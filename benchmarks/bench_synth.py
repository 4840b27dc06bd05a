"""Benchmark of the synthetic scene generator on one core: time per stage and peak memory per scene.

Run: ``.venv/bin/python benchmarks/bench_synth.py [--scenes 3] [--size 3840x2160]``.
Target (issue "Foundation"): one 3840x2160 scene including PNG writing under 5 s and 2 GB on one core.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402

from assurance.dataio.uavid import sample_paths, write_image  # noqa: E402
from assurance.files import atomic_write_bytes  # noqa: E402
from assurance.scenes.generate import (  # noqa: E402
    default_geometry,
    encode_labels,
    generate_world,
    scene_meta,
    scene_seed,
)
from assurance.scenes.renderer import render  # noqa: E402


def one_scene(root: Path, index: int, seed: int, size: tuple[int, int]) -> dict[str, float]:
    """Generate, render and write one scene; wall seconds per stage and total CPU seconds."""
    t = {"cpu0": time.process_time(), "t0": time.perf_counter()}
    g = default_geometry(size)
    world = generate_world(seed, geometry=g)
    t["world"] = time.perf_counter()
    out = render(world, g)
    t["render"] = time.perf_counter()
    img_path, lab_path, meta_path = sample_paths(root, "seq00", f"{index:06d}")
    write_image(img_path, out.image, compression=1)
    atomic_write_bytes(lab_path, encode_labels(out.labels))
    meta = scene_meta(world, g, out.labels, "train")
    atomic_write_bytes(meta_path, json.dumps(meta, separators=(",", ":")).encode())
    t["write"] = time.perf_counter()
    return {"world_s": t["world"] - t["t0"], "render_s": t["render"] - t["world"],
            "write_s": t["write"] - t["render"], "total_s": t["write"] - t["t0"],
            "cpu_s": time.process_time() - t["cpu0"], "style": world.style}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=3)
    parser.add_argument("--size", default="3840x2160")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        t0 = time.perf_counter()
        one_scene(root / "warm", 0, scene_seed("train", 999_999), (256, 144))  # builds the noise tiles once
        cold = time.perf_counter() - t0
        rows = [one_scene(root, i, scene_seed("train", i, args.seed), size) for i in range(args.scenes)]
        tracemalloc.start()
        one_scene(root / "mem", 0, scene_seed("train", args.seed), size)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    maxrss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"synthetic scenes {size[0]}x{size[1]}, one core (cv2 threads 1); one-off warm-up {cold:.2f} s")
    print(f"{'scene':>5} {'style':<12} {'world s':>8} {'render s':>9} {'write s':>8} {'total s':>8} {'cpu s':>6}")
    for i, r in enumerate(rows):
        print(f"{i:>5} {r['style']:<12} {r['world_s']:>8.2f} {r['render_s']:>9.2f} {r['write_s']:>8.2f} "
              f"{r['total_s']:>8.2f} {r['cpu_s']:>6.2f}")
    mean = {k: sum(r[k] for r in rows) / len(rows) for k in ("world_s", "render_s", "write_s", "total_s", "cpu_s")}
    print(f"{'mean':>5} {'':<12} {mean['world_s']:>8.2f} {mean['render_s']:>9.2f} {mean['write_s']:>8.2f} "
          f"{mean['total_s']:>8.2f} {mean['cpu_s']:>6.2f}")
    print(f"peak Python-tracked memory per scene (tracemalloc): {peak / 2**20:.0f} MiB; "
          f"process peak RSS: {maxrss_mb:.0f} MiB")
    load = os.getloadavg()[0]
    cpu_ok = max(r["cpu_s"] for r in rows) < 5.0 and maxrss_mb < 2048
    wall_ok = max(r["total_s"] for r in rows) < 5.0
    print(f"target (< 5 s on one core, < 2 GB per scene): CPU time {'met' if cpu_ok else 'NOT met'}, "
          f"wall time {'met' if wall_ok else 'NOT met'} (1-min load average {load:.1f} on {os.cpu_count()} cores; "
          "wall time exceeds CPU time when other processes share the cores)")


if __name__ == "__main__":
    main()
