"""Benchmark of the decision budget: how far past its budget a decision returns, and when its work stops.

    .venv/bin/python benchmarks/bench_budget.py [--image FRAME.png] [--repeats 3] [--budgets 0.001 0.5 1 3.5]

On a 3840x2160 frame (a synthetic test scene, written to a temporary folder unless ``--image`` names one),
for the deployed monitor and MC dropout (``lhd+ch+mcd:tau=0.25,n=30,rho=0.5``), each budget is run with the
hard stop (the default: ``decide`` returns the default action at the deadline) and with the cooperative
checks alone (``hard_stop=False``). Per row: the worst time ``decide`` took past its budget ("returned
+ms"), and the worst time past the budget at which the stopped decision's worker reached a checkpoint and
ended ("stopped +ms": the work still on the CPU after the caller has its answer). Target: returned +ms
< 50 ms with the hard stop, whatever the budget.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

from el.flight.pipeline import EmergencyLanding, PipelineConfig

MONITORS = {"deployed": None, "mcd n=30": "lhd+ch+mcd:tau=0.25,n=30,rho=0.5"}


def _frame(tmp: str) -> Path:
    from assurance.scenes.generate import write_dataset

    write_dataset(tmp, 1, 0, "test", (3840, 2160), progress=False)
    return sorted(Path(tmp).glob("*/Images/*.png"))[0]


def _workers_done() -> float:
    """Wait for stopped decisions' worker threads to end; the time of the end."""
    for t in threading.enumerate():
        if t.name == "uav-el-decision":
            t.join()
    return time.perf_counter()


def measure(image: Path, monitor: str | None, budget: float, hard: bool, repeats: int) -> tuple[float, float, str]:
    """(worst returned overrun s, worst stopped overrun s, the last reason) over ``repeats`` decisions."""
    kw = {} if monitor is None else {"monitor": monitor}
    landing = EmergencyLanding(PipelineConfig(time_budget_s=budget, hard_stop=hard, **kw))
    worst_ret = worst_stop = float("-inf")
    reason = ""
    for _ in range(repeats):
        t0 = time.perf_counter()
        decision = landing.decide(image)
        t1 = time.perf_counter()
        t2 = _workers_done()
        worst_ret = max(worst_ret, t1 - t0 - budget)
        worst_stop = max(worst_stop, t2 - t0 - budget)
        reason = decision.reason
    return worst_ret, worst_stop, reason


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--image", type=Path, help="a 3840x2160 frame (default: a synthetic test scene)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--budgets", type=float, nargs="+", default=[0.001, 0.5, 1.0, 3.5])
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="uav-el-bench-budget-") as tmp:
        image = args.image or _frame(tmp)
        print(f"frame: {image}")
        print("| monitor | budget s | hard stop | returned +ms (worst) | stopped +ms (worst) | last reason |")
        print("|---|---|---|---|---|---|")
        worst_hard = 0.0
        for name, spec in MONITORS.items():
            for budget in args.budgets:
                for hard in (True, False):
                    ret, stop, reason = measure(image, spec, budget, hard, args.repeats)
                    if hard:
                        worst_hard = max(worst_hard, ret)
                    print(f"| {name} | {budget:g} | {'yes' if hard else 'no'} | {1000 * ret:+.0f} | "
                          f"{1000 * stop:+.0f} | {reason} |", flush=True)
    print(f"worst overrun of the returned decision with the hard stop: {1000 * worst_hard:+.0f} ms "
          "(negative: it returned before the budget, the decision being done)")
    return 0 if worst_hard < 0.05 else 1


if __name__ == "__main__":
    sys.exit(main())
