"""Campaign throughput: the effect of work sharing and of parallel workers, as ratios.

- sharing: one grid run (every configuration per task, features shared) vs the sum of
  single-configuration runs over the same tasks;
- workers: 1 vs 2 loky workers, and a Dask LocalCluster with 2 workers, on the same grid.

    .venv/bin/python benchmarks/bench_campaign.py [--data data/test] [--images 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from assurance.campaign.presets import preset_config
from assurance.campaign.run import Execution, run_campaign
from el.monitors import DEMO_GRID


def timed_run(data: str, cfg, **kw) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        run_campaign(data, Path(tmp) / "run", cfg, **kw, execution=Execution(progress=False))
        return time.perf_counter() - t


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/test")
    p.add_argument("--images", type=int, default=2)
    p.add_argument("--perturbations", nargs="+", default=["none", "fog"])
    args = p.parse_args(argv)
    if not Path(args.data).is_dir():
        print(f"{args.data}: no scenes (generate them with `uav-el synth`)", file=sys.stderr)
        return 2
    grid = preset_config("demo", images=args.images, perturbations=tuple(args.perturbations))
    tasks = args.images * len(args.perturbations)

    shared = timed_run(args.data, grid, jobs=1)
    single = sum(timed_run(args.data, preset_config("demo", images=args.images, monitors=(m,),
                                                   perturbations=tuple(args.perturbations)), jobs=1)
                 for m in DEMO_GRID)
    loky2 = timed_run(args.data, grid, jobs=2)
    dask2 = timed_run(args.data, grid, jobs=2, backend="dask")

    print(f"{tasks} tasks ({args.images} images x {len(args.perturbations)} perturbations), "
          f"{len(DEMO_GRID)} monitor configurations\n")
    print("| run | wall s | ratio |")
    print("|---|---|---|")
    print(f"| sum of {len(DEMO_GRID)} single-configuration runs, 1 worker | {single:.1f} | 1.00 |")
    print(f"| shared grid, 1 worker | {shared:.1f} | {shared / single:.2f} of single-config sum |")
    print(f"| shared grid, 2 loky workers | {loky2:.1f} | {loky2 / shared:.2f} of 1 worker |")
    print(f"| shared grid, Dask LocalCluster 2 workers | {dask2:.1f} | {dask2 / shared:.2f} of 1 worker |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
