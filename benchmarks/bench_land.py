"""`uav-el land` end to end on one frame: where the time of the command goes, and how often it reads each part.

Each round runs the real command (``assurance.cli.main(["land", FRAME, "--system", FILE])``) in a fresh interpreter
with its stages timed from outside (exclusive times; nothing in the command changes): imports, the system file
(``System.build``, with its gate sense check), the network load (``System.segmenter``), the monitor build, the gate
read(s), the frame decode(s), the flight system's remaining checks (``EmergencyLanding`` construction), the decision,
and the rest (parsing, output). It also counts how many times each part was read, and times the command itself
(``python -m assurance land ...``) and ``land --help`` as a user runs them. Best of ``--rounds``.

Without FRAME: a synthetic 1280x853 scene and a system file declaring that frame size (the shipped network, its
deployed monitor and gate), made in a temporary folder. The target with a small ONNX network is 1.0 s for the
command.

    .venv/bin/python benchmarks/bench_land.py [FRAME --system FILE] [--rounds 3] [--overlay] [--checkout DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 1.0
STAGES = ("imports", "system file", "model load", "monitor build", "gate load", "decode", "flight checks", "decision",
          "rest of the command")
CHILD = r'''
import json, sys, time
t0 = time.perf_counter()
import assurance.cli, assurance.cli.land, assurance.system.system, el.flight.pipeline, el.base.imageio
import el.monitors.frame_gate
try:
    import assurance.cli.land_run  # the command's work, its own module since issue 58
except ImportError:  # an older checkout
    pass
spent, counts, stack = {"imports": time.perf_counter() - t0}, {}, []


def timed(owner, name, stage, count=True):
    raw = vars(owner).get(name)
    if raw is None:  # an older checkout without this step
        return
    fn = raw.__func__ if isinstance(raw, classmethod) else raw

    def wrapper(*args, **kwargs):
        stack.append(0.0)
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            elapsed = time.perf_counter() - start
            spent[stage] = spent.get(stage, 0.0) + elapsed - stack.pop()
            counts[stage] = counts.get(stage, 0) + count
            if stack:
                stack[-1] += elapsed

    setattr(owner, name, classmethod(wrapper) if isinstance(raw, classmethod) else wrapper)


pipeline, System = el.flight.pipeline, assurance.system.system.System
FrameFile = getattr(pipeline, "FrameFile", pipeline)
for owner, name, stage, *count in ((System, "build", "system file"), (System, "segmenter", "model load"),
                           (pipeline, "build_monitor", "monitor build"), (pipeline, "load_frame_gate", "gate load"),
                           (el.monitors.frame_gate, "load_frame_gate", "gate load"),
                           (el.base.imageio, "_decode_frame", "decode"), (FrameFile, "read", "decode", False),
                           (pipeline.EmergencyLanding, "__init__", "flight checks"),
                           (pipeline.EmergencyLanding, "decide", "decision")):
    timed(owner, name, stage, *count)
start = time.perf_counter()
code = assurance.cli.main(["land", *sys.argv[1:]])
spent["rest of the command"] = time.perf_counter() - start - sum(v for k, v in spent.items() if k != "imports")
print(json.dumps({"code": code, "spent": spent, "counts": counts}), file=sys.stderr)
'''


def _fixture(tmp: Path) -> tuple[Path, Path]:
    """A synthetic 1280x853 scene and a system file (the shipped network) whose declared domain admits it."""
    from assurance.dataio.uavid import iter_samples
    from assurance.scenes.generate import write_dataset

    write_dataset(tmp / "data", 1, 0, "val", (1280, 853), progress=False)
    frame = next(iter(iter_samples(tmp / "data", require_labels=False))).image_path
    system = tmp / "uav-el.toml"
    system.write_text("[odd]\nheight_m = [40.0, 60.0]\npitch_deg = [36.0, 54.0]\nimage_width = [1200, 1300]\n"
                      "image_height = [800, 900]\naspect = [1.4, 1.6]\n")
    return frame, system


def _wall(args: list[str], cwd: str | None) -> float:
    """Seconds of one run of ``python ARGS`` in ``cwd`` (its output discarded)."""
    start = time.perf_counter()
    subprocess.run([sys.executable, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False, cwd=cwd)
    return time.perf_counter() - start


def _staged(command: list[str], cwd: str | None) -> dict:
    """One fresh interpreter running the command with its stages timed (the child's last stderr line)."""
    done = subprocess.run([sys.executable, "-c", CHILD, *command], capture_output=True, text=True, check=False,
                          cwd=cwd)
    lines = done.stderr.strip().splitlines()
    if not lines or not lines[-1].startswith("{"):
        raise SystemExit(f"the timed command failed:\n{done.stderr}")
    return json.loads(lines[-1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("frame", nargs="?", help="the frame (default: a synthetic 1280x853 scene)")
    p.add_argument("--system", help="system file (default: the shipped network, declaring the frame's size)")
    p.add_argument("--rounds", type=int, default=3, help="rounds; the best is shown (default 3)")
    p.add_argument("--overlay", action="store_true", help="also draw the decision (--overlay)")
    p.add_argument("--checkout", help="measure the code of another checkout with this interpreter (e.g. an export "
                                      "of an earlier commit: git archive HEAD | tar -x -C DIR)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="uav-el-bench-land-") as tmp:
        frame, system = (Path(args.frame).resolve(), args.system) if args.frame else _fixture(Path(tmp))
        command = [str(frame), *(["--system", str(Path(system).resolve())] if system else []), "--json",
                   f"{tmp}/d.json", *(["--overlay", f"{tmp}/o.png"] if args.overlay else [])]
        runs = [_staged(command, args.checkout) for _ in range(args.rounds)]
        walls = [_wall(["-m", "assurance", "land", *command], args.checkout) for _ in range(args.rounds)]
        helps = [_wall(["-m", "assurance", "land", "--help"], args.checkout) for _ in range(args.rounds)]
        bare = min(_wall(["-c", "pass"], None) for _ in range(args.rounds))
    print(f"`uav-el land {frame.name}{' --system ' + Path(system).name if system else ''}"
          f"{' --overlay' if args.overlay else ''}`, best of {args.rounds} (exit code {runs[0]['code']})\n")
    print("| stage | seconds | times |")
    print("|---|---|---|")
    print(f"| interpreter start | {bare:.3f} | |")
    for stage in STAGES:
        best = min(r["spent"].get(stage, 0.0) for r in runs)
        print(f"| {stage} | {best:.3f} | {runs[0]['counts'].get(stage, '') if stage != 'imports' else ''} |")
    total = min(sum(r["spent"].values()) for r in runs)
    print(f"| total in the command | {total:.3f} | |")
    print(f"| `python -m assurance land ...` (wall) | {min(walls):.3f} | |")
    print(f"| `python -m assurance land --help` (wall) | {min(helps):.3f} | |")
    print(f"\n{'PASS' if min(walls) <= TARGET_S else 'OVER'}  land {min(walls):.2f} s (target {TARGET_S} s with a "
          "small ONNX network)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
