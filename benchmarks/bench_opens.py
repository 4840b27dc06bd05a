"""How many times one ``uav-el`` command opens each file it reads: the measure of "read once" (issue 58).

Runs ``uav-el ARGS`` in a fresh interpreter with an audit hook (``sys.addaudithook``, event ``open``) that counts the
opens of every regular file by real path, then prints the files opened more than once (or all, with ``--all``),
most opened first, with what they are (the system file, a frame gate, a calibration card, a network, the run's
manifest). Python's own modules and the toolkit's packaged data opened by imports are left out.

    .venv/bin/python benchmarks/bench_opens.py -- land FRAME --system FILE
    .venv/bin/python benchmarks/bench_opens.py -- evidence --run runs/demo --out /tmp/r --no-pdf
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

CHILD = r'''
import collections, json, os, sys
counts = collections.Counter()
def hook(event, args):
    if event == "open" and args and isinstance(args[0], (str, bytes, os.PathLike)):
        path = os.fsdecode(args[0])
        mode = args[1] if len(args) > 1 else "r"
        flags = args[2] if len(args) > 2 else 0
        writing = (isinstance(mode, str) and any(c in mode for c in "wax+")) or (
            isinstance(flags, int) and flags & (os.O_WRONLY | os.O_RDWR))
        if not writing:
            counts[os.path.realpath(path)] += 1
sys.addaudithook(hook)
from assurance import cli
code = cli.main(sys.argv[1:])
skip = tuple(os.path.realpath(p) for p in sys.path if p) + ("/proc", "/sys", "/dev")
own = os.path.realpath(os.path.join(os.path.dirname(cli.__file__), "..", ".."))
out = {p: n for p, n in counts.items() if os.path.isfile(p) and not p.endswith((".py", ".pyc", ".so", ".pth"))
       and (p.startswith(own) or not p.startswith(skip))}
print("@@OPENS@@" + json.dumps({"code": code, "opens": out}))
'''

KINDS = (("manifest.json", "run manifest"), ("frame_gate", "frame gate"), ("calibration", "calibration card"),
         (".onnx", "network (ONNX)"), (".pt", "network (weights)"), ("learned", "learned monitor"),
         (".toml", "system file"), ("labels", "label set"), ("hierarchy", "hierarchy"))


def kind(path: str) -> str:
    """What a file is, by its name (for the table)."""
    name = Path(path).name
    return next((k for key, k in KINDS if key in name), "")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--all", action="store_true", help="list every file read, not only those read more than once")
    p.add_argument("args", nargs=argparse.REMAINDER, help="the uav-el command and its arguments (after --)")
    a = p.parse_args()
    args = a.args[1:] if a.args[:1] == ["--"] else a.args
    if not args:
        p.error("give the uav-el command after --")
    run = subprocess.run([sys.executable, "-c", CHILD, *args], capture_output=True, text=True, check=False)
    line = next((ln for ln in run.stdout.splitlines() if ln.startswith("@@OPENS@@")), None)
    if line is None:
        print(run.stderr.strip()[-2000:], file=sys.stderr)
        return 2
    doc = json.loads(line[len("@@OPENS@@"):])
    rows = sorted(((n, path) for path, n in doc["opens"].items() if a.all or n > 1), reverse=True)
    print(f"uav-el {' '.join(args)}  (exit {doc['code']})")
    print(f"{'opens':>5}  {'what':<18} file")
    for n, path in rows:
        print(f"{n:>5}  {kind(path):<18} {path}")
    if not rows:
        print("  every file read once")
    return 0


if __name__ == "__main__":
    sys.exit(main())
