"""Time each perturbation on a full-resolution frame (default 3840 x 2160, severity 3).

Run: ``.venv/bin/python benchmarks/bench_perturbations.py [--repeat 5] [--severity 3]``

Prints one row per perturbation: median wall time over ``--repeat`` runs (after one warm-up run)
and the peak memory allocated during one run on top of the input image, as traced by
``tracemalloc`` (numpy arrays, including those OpenCV returns; OpenCV's internal scratch buffers
are not traced). Timings depend on the machine and on what else runs on it.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
import tracemalloc

import cv2
import numpy as np

from assurance.perturbations import PERTURBATIONS, perturb


def frame(width: int, height: int, seed: int = 0) -> np.ndarray:
    """A seeded, smoothly textured RGB frame (uint8)."""
    rng = np.random.default_rng(seed)
    coarse = rng.integers(0, 256, size=(max(2, height // 16), max(2, width // 16), 3), dtype=np.uint8)
    img = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    img += rng.integers(0, 8, size=img.shape, dtype=np.uint8)  # fine grain
    return img


def measure(image: np.ndarray, name: str, severity: int, repeat: int) -> tuple[float, float]:
    """(median ms, peak traced MB) of ``perturb(image, name, severity, rng)``."""
    perturb(image, name, severity, np.random.default_rng(0))  # warm-up (page faults, caches)
    times = []
    for i in range(repeat):
        rng = np.random.default_rng(i)
        t0 = time.perf_counter()
        perturb(image, name, severity, rng)
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        out = perturb(image, name, severity, np.random.default_rng(0))
        peak = tracemalloc.get_traced_memory()[1] - base
        del out
    finally:
        tracemalloc.stop()
    return 1000 * statistics.median(times), peak / 2**20


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=3840)
    parser.add_argument("--height", type=int, default=2160)
    parser.add_argument("--severity", type=int, default=3, choices=range(1, 6))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--only", nargs="*", default=None, help="perturbation names (default: all)")
    args = parser.parse_args(argv)

    names = args.only or list(PERTURBATIONS)
    image = frame(args.width, args.height)
    print(
        f"# {args.width}x{args.height} RGB uint8 ({image.nbytes / 2**20:.1f} MB), severity {args.severity}, "
        f"median of {args.repeat}; numpy {np.__version__}, OpenCV {cv2.__version__}, "
        f"{platform.processor() or platform.machine()}, cv2 threads {cv2.getNumThreads()}"
    )
    print(f"{'name':<16} {'severity':>8} {'median ms':>10} {'peak MB':>8}")
    for name in names:
        ms, mb = measure(image, name, args.severity, args.repeat)
        print(f"{name:<16} {args.severity:>8} {ms:>10.1f} {mb:>8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
