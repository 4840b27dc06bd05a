"""`uav-el table` on a campaign run: its wall time, and the bootstrap's share of it.

    .venv/bin/python benchmarks/bench_table.py [--run runs/demo] [--old]

Times the command as a user runs it (a fresh process: ``uav-el table RUN --compare --out TMP -q``), then once
more in this process with its two bootstraps timed apart: the results table's intervals (``image_bootstrap``
called by ``ScenarioMetrics``: gains, overhead, pooled ratios) and the AUROC table's
(``scores.grouped_auroc_ci``, 1000 resamples of images per configuration). ``--old`` also times the AUROC
statistic as it was before issue 52 (one scikit-learn ``roc_auc_score`` call per resample, about 30 s on the
demo run) and checks that both write the same files, byte for byte. Target (issue 52): the demo run's table
(60 tasks, 5 configurations) in <= 10 s on the 2-core CPU; it took about 32 s.
"""

from __future__ import annotations

import argparse
import contextlib
import filecmp
import io
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from assurance.analysis import metrics, scores
from assurance.cli import main as cli

TARGET_S = 10.0
FILES = ("results.csv", "results.md", "comparison.csv")


class SklearnGroupedAuroc:
    """The AUROC statistic before issue 52: ``scores.auroc`` (scikit-learn) of each resample in turn."""

    def __init__(self, inverse: Any, n_groups: int, scores_: Any, unsafe: Any) -> None:
        inverse = np.asarray(inverse)
        self.members = [np.flatnonzero(inverse == i) for i in range(n_groups)]
        self.s, self.y = np.asarray(scores_, dtype=np.float64), np.asarray(unsafe, dtype=bool)

    def __call__(self, idx: np.ndarray) -> np.ndarray:
        flat = idx.reshape(-1, idx.shape[-1])
        out = np.empty(len(flat))
        for b, sample in enumerate(flat):
            rows = np.concatenate([self.members[i] for i in sample])
            out[b] = scores.auroc(self.s[rows], self.y[rows])
        return out.reshape(idx.shape[:-1])


@contextlib.contextmanager
def timed(module: Any, name: str, spent: list[float]) -> Iterator[None]:
    """``module.name`` wrapped so that the seconds spent in it add up in ``spent[0]``."""
    original: Callable[..., Any] = getattr(module, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - t

    setattr(module, name, wrapper)
    try:
        yield
    finally:
        setattr(module, name, original)


def fresh_process(run: str, out: Path) -> float:
    """Wall seconds of ``uav-el table`` in a new Python process (imports included)."""
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "assurance", "table", run, "--compare", "--out", str(out), "-q"],
                   check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def in_process(run: str, out: Path, statistic: type | None = None) -> tuple[float, float, float]:
    """Wall seconds of the command in this process, and of its two bootstraps (results table, AUROC table)."""
    table_s, auroc_s = [0.0], [0.0]
    with contextlib.ExitStack() as stack:
        stack.enter_context(timed(metrics, "image_bootstrap", table_s))
        stack.enter_context(timed(scores, "grouped_auroc_ci", auroc_s))
        if statistic is not None:
            stack.enter_context(_swapped(scores, "GroupedAuroc", statistic))
        stack.enter_context(contextlib.redirect_stdout(io.StringIO()))
        t = time.perf_counter()
        code = cli(["table", run, "--compare", "--out", str(out), "-q"])
        wall = time.perf_counter() - t
    if code:
        raise SystemExit(f"uav-el table {run} exited {code}")
    return wall, table_s[0], auroc_s[0]


@contextlib.contextmanager
def _swapped(module: Any, name: str, value: Any) -> Iterator[None]:
    original = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, original)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run", default="runs/demo", help="campaign run (default runs/demo, written by `make demo`)")
    p.add_argument("--old", action="store_true",
                   help="also time the AUROC statistic before issue 52 (scikit-learn per resample; ~30 s)")
    args = p.parse_args(argv)
    if not (Path(args.run) / "manifest.json").is_file():
        print(f"{args.run}: no campaign run (`make demo` writes runs/demo)", file=sys.stderr)
        return 2

    with tempfile.TemporaryDirectory() as tmp:
        outs = {name: Path(tmp) / name for name in ("fresh", "new", "old")}
        fresh = fresh_process(args.run, outs["fresh"])
        rows = [("vectorised AUROC (this code)", *in_process(args.run, outs["new"]))]
        if args.old:
            rows.append(("scikit-learn per resample (before)", *in_process(args.run, outs["old"],
                                                                            SklearnGroupedAuroc)))
        same = all(filecmp.cmp(outs["fresh"] / f, outs[k] / f, shallow=False)
                   for k in outs if k != "fresh" and outs[k].is_dir() for f in FILES)

    print(f"uav-el table {args.run} --compare (fresh process: {fresh:.2f} s wall)\n")
    print("| AUROC statistic | table command s | results-table bootstrap s | AUROC bootstrap s | bootstrap share |")
    print("|---|---|---|---|---|")
    for name, wall, table_s, auroc_s in rows:
        print(f"| {name} | {wall:.2f} | {table_s:.2f} | {auroc_s:.2f} | {(table_s + auroc_s) / wall:.0%} |")
    if not args.old:
        print("| scikit-learn per resample (before; measured on the demo run, issue 52) | ~32 | - | ~30 | ~95% |")
    print(f"\nthe files written ({', '.join(FILES)}) are {'the same' if same else 'NOT the same'} in every path")
    print(f"{'PASS' if fresh <= TARGET_S else 'FAIL'}  table command {fresh:.2f} s <= {TARGET_S:.0f} s")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
