"""Benchmark of the CM post-processing at the working resolution (1024x576).

    .venv/bin/python benchmarks/bench_core.py [--maps 20] [--dbscan-maps 3] [--seed 0]

Generates urban-like class-probability maps (roads whose width grows towards the bottom of the
oblique view, buildings, parked cars along the roads, trees, lawns, clutter, people; softened at
the class borders like a softmax), times each CM stage (valid pixels, regions, representatives,
ranking + pruning) with the fast region path, then the DBSCAN reference on the same valid masks,
and prints a table. Targets: regions >= 100x faster than DBSCAN; whole post-processing < 50 ms
median. Also times the conservative pooling of a 3840x2160 label map (ground-truth pipeline).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import cv2
import numpy as np

from el.classes.labels import CLASS_IDS, NUM_CLASSES, UAVID
from el.geometry.config import CoreConfig
from el.landing import candidates as cand
from el.landing import regions as reg
from el.landing.core import probs_from_labels, reachable_working_row, run_core

W_FULL, H_FULL = 3840, 2160


def urban_labels(rng: np.random.Generator, width: int = 1024, height: int = 576) -> np.ndarray:
    """A random oblique urban label map (H, W) uint8: sizes grow towards the bottom rows."""
    s = width / 1024.0
    ids = np.full((height, width), CLASS_IDS["low_vegetation"], dtype=np.uint8)

    def near(y: float) -> float:  # apparent size factor: far rows small, near rows large
        return 0.5 + 1.2 * y / height

    for _ in range(int(rng.integers(6, 14))):  # clutter and lawns of other kinds
        x, y = int(rng.integers(width)), int(rng.integers(height))
        ax, ay = int(rng.integers(20, 120) * s * near(y)), int(rng.integers(10, 60) * s * near(y))
        cls = int(rng.choice([CLASS_IDS["clutter"], CLASS_IDS["clutter"], CLASS_IDS["tree"]]))
        cv2.ellipse(ids, (x, y), (ax, ay), float(rng.uniform(0, 180)), 0, 360, cls, -1)
    roads = []
    for _ in range(int(rng.integers(2, 5))):  # streets: roughly horizontal and converging ones
        if rng.random() < 0.5:
            y0, y1 = int(rng.integers(0, height)), int(rng.integers(0, height))
            p0, p1 = (0, y0), (width - 1, y1)
        else:
            x0 = int(rng.integers(0, width))
            p0, p1 = (x0 + int(rng.integers(-200, 200) * s), 0), (x0 + int(rng.integers(-400, 400) * s), height - 1)
        roads.append((p0, p1))
        n = 12
        for k in range(n):  # draw in pieces so the width grows with the row
            a = (p0[0] + (p1[0] - p0[0]) * k / n, p0[1] + (p1[1] - p0[1]) * k / n)
            b = (p0[0] + (p1[0] - p0[0]) * (k + 1) / n, p0[1] + (p1[1] - p0[1]) * (k + 1) / n)
            t = max(2, int(14 * s * near((a[1] + b[1]) / 2)))
            cv2.line(ids, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), CLASS_IDS["road"], t)
    for _ in range(int(rng.integers(8, 20))):  # buildings
        x, y = int(rng.integers(width)), int(rng.integers(height))
        w, h = int(rng.integers(30, 140) * s * near(y)), int(rng.integers(20, 90) * s * near(y))
        ids[y : y + h, x : x + w] = CLASS_IDS["building"]
    for (p0, p1) in roads:  # cars along the roads
        for _ in range(int(rng.integers(5, 20))):
            u = rng.random()
            x = int(p0[0] + (p1[0] - p0[0]) * u + rng.integers(-12, 12) * s)
            y = int(p0[1] + (p1[1] - p0[1]) * u + rng.integers(-8, 8) * s)
            w, h = max(2, int(9 * s * near(y))), max(2, int(5 * s * near(y)))
            cls = CLASS_IDS["static_car"] if rng.random() < 0.7 else CLASS_IDS["moving_car"]
            ids[max(y, 0) : max(y, 0) + h, max(x, 0) : max(x, 0) + w] = cls
    for _ in range(int(rng.integers(10, 40))):  # trees
        x, y = int(rng.integers(width)), int(rng.integers(height))
        r = int(rng.integers(5, 18) * s * near(y))
        cv2.circle(ids, (x, y), r, CLASS_IDS["tree"], -1)
    for _ in range(int(rng.integers(5, 30))):  # people
        x, y = int(rng.integers(width)), int(rng.integers(height))
        ids[y : y + 2, x : x + 2] = CLASS_IDS["human"]
    return ids


def soft_probs(ids: np.ndarray, rng: np.random.Generator, sigma: float = 1.5) -> np.ndarray:
    """Softmax-like probabilities: a blurred one-hot with a little noise, renormalised, float32."""
    probs = np.zeros((NUM_CLASSES, *ids.shape), dtype=np.float32)
    np.put_along_axis(probs, ids[None].astype(np.intp), 1.0, axis=0)
    for c in range(NUM_CLASSES):
        probs[c] = cv2.GaussianBlur(probs[c], (0, 0), sigma)
    probs += rng.uniform(0, 0.02, size=probs.shape).astype(np.float32)
    probs /= probs.sum(axis=0, keepdims=True)
    return probs


def _stats(values: list[float]) -> tuple[float, float]:
    v = sorted(values)
    return statistics.median(v), v[min(len(v) - 1, int(round(0.9 * (len(v) - 1))))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", type=int, default=20, help="number of maps (default: %(default)s)")
    parser.add_argument("--dbscan-maps", type=int, default=3,
                        help="maps on which the DBSCAN reference also runs (slow; default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    config = CoreConfig()
    w, h = 1024, 576
    maps = [soft_probs(urban_labels(rng), rng) for _ in range(args.maps)]
    run_core(maps[0], (W_FULL, H_FULL), config, labels=UAVID)  # warm-up: imports, caches

    stages = ["valid_s", "regions_s", "representatives_s", "ranking_s", "total_s"]
    fast: dict[str, list[float]] = {k: [] for k in stages}
    counts = []
    for probs in maps:
        result = run_core(probs, (W_FULL, H_FULL), config, labels=UAVID)
        for k in stages:
            fast[k].append(result.timings[k])
        counts.append(result.stats)

    # The DBSCAN reference on the same valid masks, and the fast path on them again.
    geo = config.geometry(w, h)
    radii = cand.row_radii(geo, config.safety, config.mode)
    min_row, _ = reachable_working_row((W_FULL, H_FULL), (w, h), config)
    ref_rows = []
    for probs in maps[: args.dbscan_maps]:
        vp = cand.valid_pixels(cand.forbidden_from_probs(probs, labels=UAVID), radii, min_row=min_row)
        t0 = time.perf_counter()
        ours = reg.regions_fast(vp.valid)
        t1 = time.perf_counter()
        ref = reg.regions_dbscan(vp.valid)
        t2 = time.perf_counter()
        same = bool((ours.core == ref.core).all()) and reg.same_partition(ours.labels[ours.core], ref.labels[ref.core])
        ref_rows.append((int(vp.valid.sum()), t1 - t0, t2 - t1, same))
    dbscan_total = []
    for probs in maps[: args.dbscan_maps]:
        dbscan = run_core(probs, (W_FULL, H_FULL), CoreConfig(region_method="dbscan"), labels=UAVID)
        dbscan_total.append(dbscan.timings["total_s"])

    labels_4k = urban_labels(np.random.default_rng(args.seed + 1), W_FULL, H_FULL)
    pool_times = []
    for _ in range(3):
        t0 = time.perf_counter()
        probs_from_labels(labels_4k, (w, h), labels=UAVID)
        pool_times.append(time.perf_counter() - t0)

    print(f"CM post-processing on {args.maps} maps of {w}x{h} (input {W_FULL}x{H_FULL}), "
          f"mode={config.mode}, N*={config.n_star}; median valid pixels "
          f"{int(statistics.median(c['valid_pixels'] for c in counts))}, regions "
          f"{int(statistics.median(c['regions'] for c in counts))}, candidates "
          f"{int(statistics.median(c['candidates'] for c in counts))}")
    print()
    print(f"{'stage':<28}{'median ms':>12}{'p90 ms':>12}")
    print("-" * 52)
    for k in stages:
        med, p90 = _stats(fast[k])
        name = "TOTAL (fast path)" if k == "total_s" else k[:-2]
        print(f"{name:<28}{1000 * med:>12.2f}{1000 * p90:>12.2f}")
    if dbscan_total:
        med, p90 = _stats(dbscan_total)
        print(f"{'TOTAL (DBSCAN reference)':<28}{1000 * med:>12.1f}{1000 * p90:>12.1f}")
    med, p90 = _stats(pool_times)
    print(f"{'pooling 3840x2160 labels':<28}{1000 * med:>12.1f}{1000 * p90:>12.1f}")
    if ref_rows:
        print()
        print(f"{'map':<6}{'valid px':>10}{'fast ms':>10}{'DBSCAN ms':>12}{'speed-up':>10}  same core partition")
        print("-" * 70)
        for i, (n, tf, td, same) in enumerate(ref_rows):
            print(f"{i:<6}{n:>10}{1000 * tf:>10.2f}{1000 * td:>12.1f}{td / tf:>9.0f}x  {same}")
    ok_total = _stats(fast["total_s"])[0] < 0.050
    ok_regions = all(td / tf >= 100 for _, tf, td, _ in ref_rows)
    ok_same = all(same for *_, same in ref_rows)
    print()
    print(f"targets: total < 50 ms median: {'met' if ok_total else 'MISSED'}; "
          f"regions >= 100x DBSCAN: {'met' if ok_regions else 'MISSED'}; "
          f"same core partition: {'yes' if ok_same else 'NO'}")
    return 0 if ok_same else 1


if __name__ == "__main__":
    sys.exit(main())
