"""Fault-injection cases: bounded resources and no silent loss (rows ``R1``..``R15`` of the table).

Each case injects one hostile input into copies under the workspace (``assurance.fault_injection.case``) and
returns the ``uav-el`` command that must refuse it, bound it or survive it.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import zlib
from collections.abc import Callable
from pathlib import Path

from assurance.fault_injection.case import Case, campaign_argv, copy_run, first_image, save_tiny_weights
from el.flight.pipeline import DEPLOYED_CALIBRATION, DEPLOYED_MONITOR
from el.monitors.calibration import card_document

YAML_BOMB = "".join(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}" if i else '"lol"'] * 9) + "]\n" for i in range(9))


def _png(width: int, height: int, rows: bytes | None, *, depth: int = 8, colour: int = 2) -> bytes:
    """A PNG with this header; ``rows``: the filtered scanlines (None: an empty IDAT, a header only)."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", rows if rows is not None else b"")
            + chunk(b"IEND", b""))


def _header_bomb(ws: Path) -> list[str]:
    bomb = ws / "bomb-header.png"
    bomb.write_bytes(_png(100_000, 100_000, None))
    return ["land", bomb, "--weights", ws / "tiny.pt", "--monitor", "lhd"]


def _huge_png(ws: Path) -> list[str]:
    """A real, decodable 30000 x 30000 PNG (1-bit grey, ~110 kB): 900 Mpx once decoded."""
    side = 30_000
    row = b"\x00" * (1 + side // 8)
    z = zlib.compressobj(9)
    data = b"".join(z.compress(row) for _ in range(side)) + z.flush()
    big = ws / "huge.png"
    big.write_bytes(_png(side, side, data, depth=1, colour=0))
    return ["land", big, "--weights", ws / "tiny.pt", "--monitor", "lhd"]


def _yaml_bomb(ws: Path) -> list[str]:
    w = ws / "waivers-bomb.yaml"
    w.write_text(YAML_BOMB + "waivers:\n  - {id: EL-R01, reason: *l8, tracked_by: x, owner: x, expires: 2099-01-01}\n")
    return ["evidence", "--run", ws / "run", "--out", ws / "rep-yaml", "--no-pdf", "--boot", "20", "--waivers", w]


def _jobs(ws: Path) -> list[str]:
    run, _ = copy_run(ws, "run-jobs")
    return campaign_argv(ws, run, "--jobs", "1000")


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return ""


SLOW_MONITORS = ("--monitors", "lhd+mcd:n=1000,rho=0.5", "lhd+mcd:n=1000,rho=0.75", "lhd+mcd:n=1000,rho=0.9")
"""About 15 s a task on the workspace's tiny network: the workers are busy when the campaign is killed."""


WORKER_MARKS = {"loky": "popen_loky", "dask": "spawn_main"}
"""How a backend's worker processes are told apart from the campaign's other children (their command line)."""


def killed_campaign_survivors(ws: Path, out: Path, *, backend: str = "loky", timeout_s: float = 120.0,
                              settle_s: float = 5.0) -> list[int]:
    """SIGKILL a 2-worker campaign (a subprocess on ``backend``, :data:`SLOW_MONITORS`) once its workers have run
    for ``settle_s``; the worker pids still alive 3 s later (each then killed, so nothing is left behind).
    RuntimeError when two workers were not seen (nothing would have been tested)."""
    argv = [sys.executable, "-m", "assurance",
            *map(str, campaign_argv(ws, out, *SLOW_MONITORS, "--jobs", "2", "--backend", backend))]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: list[int] = []
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and proc.poll() is None and len(workers) < 2:
        time.sleep(0.2)
        workers = [p for p in _children(proc.pid) if WORKER_MARKS[backend] in _cmdline(p)]
    if len(workers) < 2:
        proc.kill()
        proc.wait()
        raise RuntimeError(f"the {backend} campaign showed {len(workers)} of its 2 workers in {timeout_s:.0f} s")
    time.sleep(settle_s)  # the workers have imported the toolkit and started their tasks
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    time.sleep(3.0)
    alive = [p for p in workers if Path(f"/proc/{p}").exists()]
    for p in alive:  # leave nothing behind
        os.kill(p, signal.SIGKILL)
    return alive


def _orphans_on(backend: str) -> Callable[[Path], list[str]]:
    """The case: a ``backend`` campaign SIGKILLed while its 2 workers run; none may survive; then the re-run."""
    def orphans(ws: Path) -> list[str]:
        if not sys.platform.startswith("linux"):
            return ["table", ws / "run", "--boot", "20"]
        run = ws / f"run-killed-{backend}"
        try:
            alive = killed_campaign_survivors(ws, run, backend=backend)
        except RuntimeError as exc:  # the row fails and says why
            return ["table", ws / f"not-tested: {exc}"]
        if alive:  # the row fails and names them
            return ["table", ws / f"workers-survived-{'-'.join(map(str, alive))}"]
        return campaign_argv(ws, run, *SLOW_MONITORS, "--jobs", "2", "--backend", backend)  # the re-run completes it

    return orphans


def _colliding_frames(ws: Path) -> list[str]:
    src = first_image(ws)
    seq = ws / "data-collide" / "seq00"
    for sub, path in (("Images", src), ("Labels", src.parent.parent / "Labels" / src.name)):
        (seq / sub).mkdir(parents=True, exist_ok=True)
        for stem in ("a b", "a_b"):
            shutil.copy(path, seq / sub / f"{stem}.png")
    return campaign_argv(ws, ws / "run-collide", data=ws / "data-collide")


def _meta_changed(ws: Path) -> list[str]:
    """The run made on a copy of the data, then one scene's meta/*.json edited: the re-run must see it."""
    data = ws / "data-meta"
    shutil.copytree(ws / "data", data)
    run, _ = copy_run(ws, "run-meta")
    man = json.loads((run / "manifest.json").read_text())
    man["data"]["path"] = str(data.resolve())
    (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True))
    meta = sorted(data.glob("*/meta/*.json"))[0]
    doc = json.loads(meta.read_text())
    doc["edited"] = True
    meta.write_text(json.dumps(doc))
    return campaign_argv(ws, run, data=data)


def _config_fault(ws: Path) -> list[str]:
    return campaign_argv(ws, ws / "run-nan", weights=save_tiny_weights(ws / "nan-campaign.pt", nan=True))


def _corrupt_index(ws: Path) -> list[str]:
    run, _ = copy_run(ws, "run-index")
    (run / "shards.json").write_text("{ not json")
    return campaign_argv(ws, run)


def _exif(ws: Path) -> list[str]:
    from PIL import Image

    img = Image.open(first_image(ws)).convert("RGB")
    exif = Image.Exif()
    exif[0x0112] = 3  # rotated 180 degrees
    path = ws / "exif3.jpg"
    img.save(path, quality=95, exif=exif.tobytes())
    return ["land", path, "--weights", ws / "tiny.pt", "--monitor", "lhd"]


def _seed(ws: Path) -> list[str]:
    return campaign_argv(ws, ws / "run-seed", "--seed", str(2**64))


def _card_threshold(ws: Path) -> list[str]:
    """A system deploying the shipped spec on the shipped card re-hashed at another threshold (0.9)."""
    body = dict(json.loads(DEPLOYED_CALIBRATION.read_text())["body"])
    body.update(threshold=0.9, spec=f"{body['monitor']},threshold=0.9")
    (ws / "card-0.9.json").write_text(json.dumps(card_document(body)))
    system = ws / "system-card.toml"
    system.write_text(f'[monitor]\nspec = "{DEPLOYED_MONITOR}"\ncalibration = "card-0.9.json"\n')
    return ["land", first_image(ws), "--system", system]


BOUNDS_CASES: tuple[Case, ...] = (
    Case("R1-pixel-header", "a 57-byte PNG header claiming 100000x100000 pixels", _header_bomb, 2,
         "exceeds the limit"),
    Case("R2-huge-png", "a real 30000x30000 PNG (1-bit grey, ~110 kB; 900 Mpx decoded)", _huge_png, 2,
         "refused before decoding"),
    Case("R3-budget-in-stage", "land --budget 0.001 (the first stage alone takes longer)",
         lambda ws: ["land", first_image(ws), "--weights", ws / "tiny.pt", "--monitor", "lhd", "--budget", "0.001"],
         0, "reason: timeout", "decision:"),
    Case("R4-yaml-alias-bomb", "waivers file whose reason is a 9-level YAML alias bomb", _yaml_bomb, 2,
         "aliases are not allowed"),
    Case("R5-jobs-1000", "campaign --jobs 1000", _jobs, 0, "exceeds the", "warning"),
    Case("R6-workers-die-with-parent", "a 2-worker campaign SIGKILLed while its workers run; no worker may "
         "survive it (3 s later), then the re-run completes it", _orphans_on("loky"), 0, "0 already done, of 2",
         "task(s) run"),
    Case("R7-seed-2^64", "campaign --seed 2^64", _seed, 2, "seed must be an integer >= 0"),
    Case("R8-colliding-frames", "frames 'a b' and 'a_b' in one sequence", _colliding_frames, 0,
         "2 task(s) run", "task(s) run"),
    Case("R9-meta-changed", "a scene's meta/*.json edited after the run, then the run resumed", _meta_changed, 2,
         "differs in 'data'"),
    Case("R10-config-fault", "campaign on weights whose every parameter is NaN (every task faults)",
         _config_fault, 2, "configuration reason"),
    Case("R11-corrupt-index", "shards.json overwritten with garbage, then the advised re-run", _corrupt_index, 0,
         "rebuilt from", "shards.json"),
    Case("R12-exif-orientation", "JPEG with EXIF orientation 3 (upside down)", _exif, 0, "EXIF orientation 3",
         "EXIF"),
    Case("R13-threshold-range", "land --monitor lhd:threshold=1e300",
         lambda ws: ["land", first_image(ws), "--weights", ws / "tiny.pt", "--monitor", "lhd:threshold=1e300"], 2,
         "outside the monitor's score range"),
    Case("R14-dask-workers-die-with-parent", "R6 on --backend dask (a local cluster of 2 worker processes)",
         _orphans_on("dask"), 0, "0 already done, of 2", "task(s) run"),
    Case("R15-card-threshold", "a system deploying the shipped spec on the shipped card re-hashed at threshold 0.9",
         _card_threshold, 2, "but its calibration card has threshold 0.9"),
)
