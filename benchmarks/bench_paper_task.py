"""Time of one campaign task with the paper's 21 configurations, by stage, on one thread.

A paper campaign is 420 such tasks on 2 workers, so its wall time is about 420 x (task time) / 2;
this benchmark measures the task time without running the whole campaign (before/after an
optimisation: run it at both commits on the same scenes).

    .venv/bin/python benchmarks/bench_paper_task.py [--data data/test] [--images 4] [--perturbation none]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

STAGES = ("read_s", "perturb_s", "segmentation_s", "candidates_s", "monitoring_s", "total_s")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/test")
    p.add_argument("--images", type=int, default=4, help="first N scenes (default 4)")
    p.add_argument("--perturbation", default="none")
    p.add_argument("--weights", help="weights file (default: the shipped model)")
    args = p.parse_args(argv)
    if not Path(args.data).is_dir():
        print(f"{args.data}: no scenes (generate them with `uav-el synth`)", file=sys.stderr)
        return 2

    import torch

    from assurance.campaign.presets import preset_config
    from assurance.campaign.run import plan, run_task
    from el.segmentation.factory import load_model

    torch.set_num_threads(1)
    cfg = preset_config("paper", images=args.images, perturbations=(args.perturbation,), weights=args.weights)
    segmenter = load_model(args.weights, threads=1)
    rows = []
    for task in plan(args.data, cfg):
        t = time.perf_counter()
        out = run_task(task, cfg, segmenter)
        image = out["images"][0]
        if image.get("fault"):
            print(f"{task.sample.key}: {image['fault']}", file=sys.stderr)
            return 1
        rows.append({**{s: image[s] for s in STAGES}, "candidates": image["candidates"],
                     "wall_s": time.perf_counter() - t})
    cands = sum(r["candidates"] for r in rows)
    print(f"paper grid (21 configurations), perturbation {args.perturbation}, {len(rows)} scenes, "
          f"{cands} candidates, 1 thread\n")
    print(f"| {'stage':<16} | {'sum s':>8} | {'median per task s':>18} |")
    print(f"|{'-' * 18}|{'-' * 10}|{'-' * 20}|")
    for s in STAGES:
        vals = [r[s] for r in rows]
        print(f"| {s:<16} | {sum(vals):>8.2f} | {statistics.median(vals):>18.2f} |")
    mon = sum(r["monitoring_s"] for r in rows)
    print(f"\nmonitoring per candidate: {mon / max(cands, 1):.3f} s (all 21 configurations, shared work)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
