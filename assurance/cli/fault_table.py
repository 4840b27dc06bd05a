"""``uav-el fault-table``: replay the fault-injection cases through the command line and write the table."""

from __future__ import annotations

import argparse
import contextlib
import logging
import tempfile
from collections.abc import Iterator
from pathlib import Path

from assurance.errors import CommandError

HELP = ("replay the fault-injection cases (hostile users, bad inputs, bounded resources, forged evidence, the "
        "auditor's trust boundary) through the command line in a scratch workspace and write the table (case, exit "
        "code, outcome) as CSV and Markdown; prints one line (the table with -v, the cases that misbehaved "
        "always); exit 1 when a case does not behave as expected")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, default=Path("reports") / "faults.csv", metavar="FAULTS.csv",
                   help="the table (CSV; the Markdown is written beside it as .md) (default: %(default)s)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--cases", nargs="+", metavar="ID", help="replay only these cases (default: all)")
    which.add_argument("--quick", action="store_true",
                       help="replay a representative slice (one or two cheap cases of each family; make demo); the "
                            "report then says how many of the cases its table holds")
    p.add_argument("--list", action="store_true", help="list the cases and exit")


@contextlib.contextmanager
def _case_logs_hidden(hide: bool) -> Iterator[None]:
    """The log lines of the injected faults (each case's own ERROR lines) kept off the terminal unless asked for
    (-v): a case's outcome is its exit code and captured output, never these lines."""
    handlers = list(logging.getLogger().handlers) if hide else []
    levels = [h.level for h in handlers]
    for h in handlers:
        h.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for h, level in zip(handlers, levels, strict=True):
            h.setLevel(level)


def run(args: argparse.Namespace) -> int:
    import torch

    from assurance.fault_injection import table as fi  # deferred: pandas, weasyprint; keeps fault-table --help light

    if args.list:
        for c in fi.CASES:
            print(f"{c.id}: {c.injected} (expected exit {c.expected})")
        return 0
    if args.out.suffix != ".csv":
        raise CommandError(f"--out {args.out}: expected a .csv file name")
    if args.out.is_dir():
        raise CommandError(f"--out {args.out}: is a folder")
    cases = fi.CASES
    if args.quick:
        cases = tuple(c for c in fi.CASES if c.id in fi.QUICK)
    if args.cases:
        known = {c.id for c in fi.CASES}
        unknown = [c for c in args.cases if c not in known]
        if unknown:
            raise CommandError(f"unknown case(s): {', '.join(unknown)} (see --list)")
        cases = tuple(c for c in fi.CASES if c.id in args.cases)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny tensors: one thread is faster
    verbose = getattr(args, "verbose", 0)
    try:
        with tempfile.TemporaryDirectory(prefix="uav-el-faults-") as tmp, _case_logs_hidden(not verbose):
            ws = fi.build_workspace(tmp, main=args.cli_main)
            rows = fi.run_cases(ws, cases, main=args.cli_main)
    finally:
        torch.set_num_threads(threads)
    csv_path, md_path = fi.write_table(rows, args.out)
    failed = [r for r in rows if r["result"] != "pass"]
    if verbose or failed:  # the whole table at -v; else only the rows that misbehaved
        print(fi.to_markdown(rows if verbose else failed), end="")
    print(f"fault table: {len(rows) - len(failed)} of {len(rows)} case(s) behaved as expected"
          + (f"; not: {', '.join(r['case'] for r in failed)}" if failed else "") + f" ({csv_path}, {md_path})")
    return 1 if failed else 0
