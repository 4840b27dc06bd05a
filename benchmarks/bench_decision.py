"""Decision latency end to end on 3840x2160 PNG frames, per monitor configuration.

For each configuration: read the PNG, segment, find and rank candidates, walk them with the monitor
(``el.flight.pipeline.EmergencyLanding.decide`` on the file path, the call a flight computer makes).
Prints median and p95 latency, the monitoring overhead, and the peak RSS growth, and the number of
scenes on which MC dropout changes the decision compared with LHD alone. Target on the 2-core CPU:
CM + LHD decision on a 3840x2160 PNG < 1.5 s median.

    .venv/bin/python benchmarks/bench_decision.py [--data data/val] [--scenes 10] [--threads 2]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import time

import numpy as np

from assurance.dataio.uavid import iter_samples
from el.flight.pipeline import DEPLOYED_MONITOR, EmergencyLanding, PipelineConfig
from el.segmentation.factory import load_model

CONFIGS = ("none", "lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.9", "lhd+mcd:n=30,rho=0.9",
           DEPLOYED_MONITOR)
LABELS = {"none": "CM only", "lhd": "CM + LHD", "lhd+ch:tau=0.25": "CM + LHD + CH (0.25)",
          "lhd+mcd:n=10,rho=0.9": "CM + LHD + MCD n=10", "lhd+mcd:n=30,rho=0.9": "CM + LHD + MCD n=30",
          DEPLOYED_MONITOR: f"CM + deployed ({DEPLOYED_MONITOR.partition(',threshold')[0]})"}


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/val", help="UAVid-layout scenes (default data/val)")
    p.add_argument("--scenes", type=int, default=10, help="frames to decide on (default 10)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    p.add_argument("--weights", help="weights (default: the shipped model)")
    args = p.parse_args(argv)

    samples = list(iter_samples(args.data))[: args.scenes]
    if not samples:
        print(f"{args.data}: no scenes (generate them with `uav-el synth`)", file=sys.stderr)
        return 2
    seg = load_model(args.weights, threads=args.threads)
    rss0 = peak_rss_mb()
    EmergencyLanding(PipelineConfig(monitor="lhd", time_budget_s=None), segmenter=seg).decide(samples[0].image_path)

    rows, decisions = [], {}
    for spec in CONFIGS:
        system = EmergencyLanding(PipelineConfig(monitor=spec, time_budget_s=None), segmenter=seg)
        lat, over, examined = [], [], []
        decisions[spec] = []
        for s in samples:
            t = time.perf_counter()
            d = system.decide(s.image_path)
            lat.append(time.perf_counter() - t)
            over.append(d.timings.get("monitoring_s", 0.0))
            examined.append(sum(c.monitor is not None for c in d.candidates))
            decisions[spec].append((d.action, d.selected))
            if d.reason.startswith("fault"):
                print(f"{s.key}: {d.reason}", file=sys.stderr)
        rows.append((LABELS[spec], statistics.median(lat), float(np.percentile(lat, 95)),
                     statistics.median(over), float(np.mean(examined)), peak_rss_mb() - rss0))

    lhd_over = next(r[3] for r in rows if r[0] == LABELS["lhd"])
    print(f"decision latency, {len(samples)} frames of {args.data}, {args.threads} torch thread(s)\n")
    print("| configuration | median s | p95 s | monitoring median s | x LHD overhead | candidates examined"
          " | peak RSS growth MB |")
    print("|---|---|---|---|---|---|---|")
    for name, med, p95, mo, ex, rss in rows:
        ratio = f"{mo / lhd_over:.1f}" if lhd_over > 0 and name != LABELS["none"] else "-"
        print(f"| {name} | {med:.2f} | {p95:.2f} | {mo:.2f} | {ratio} | {ex:.1f} | {rss:.0f} |")
    lhd_median = next(r[1] for r in rows if r[0] == LABELS["lhd"])
    print(f"\n{'PASS' if lhd_median < 1.5 else 'FAIL'}  CM + LHD decision median {lhd_median:.2f} s < 1.5 s")
    print()
    for spec in ("lhd+mcd:n=10,rho=0.9", "lhd+mcd:n=30,rho=0.9"):
        changed = sum(a != b for a, b in zip(decisions["lhd"], decisions[spec], strict=True))
        print(f"{LABELS[spec]} changes the decision of LHD alone on {changed} of {len(samples)} scenes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
