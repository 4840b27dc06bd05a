"""Decision latency of the shipped network under torch and under ONNX Runtime, on the same 3840x2160 PNGs.

For each engine (``UAV_EL_ENGINE=torch`` / ``onnx``, chosen by :func:`el.segmentation.onnx_engine.engine_for`)
and each configuration, ``el.flight.pipeline.EmergencyLanding.decide`` on the file path (read, segment, candidates,
monitor walk), median and p95 over the frames; the engines are interleaved frame by frame (and the whole
measure repeated ``--rounds`` times) so that other load on the shared CPU hits both alike. Also counts the
frames whose decision (action, selected candidate, candidate positions) differs between the engines.
Target on 2 cores (the decision-time goal): deployed decision on a 3840x2160 PNG < 0.35 s median.

The deployed configuration is measured twice: as the flight loop judges it (``monitor.check``, one candidate at
a time) and ``batched``: the score walk's judge asks ``monitor.check_many`` for every candidate of the frame at
once (:class:`BatchedLanding`; the HD patches segmented in few passes). The batched decisions are compared with
the per-candidate ones (action, selected candidate, positions, verdicts, scores to 1e-6).

    .venv/bin/python benchmarks/bench_engines.py [--data data/test] [--scenes 10] [--threads 2] [--rounds 2]
        [--engines onnx] [--configs deployed batched] [--patch-workers N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from assurance.dataio.uavid import iter_samples
from el.base.imageio import read_image_hashed
from el.base.rgb import check_rgb
from el.flight.pipeline import DEPLOYED_MONITOR, MIN_FRAME_SIZE, EmergencyLanding, PipelineConfig
from el.monitors.patch_judge import batch_judge
from el.monitors.walk import SCORE
from el.segmentation.factory import load_model
from el.segmentation.onnx_engine import ENGINE_ENV

# name -> (monitor spec, batched judge, table label)
CONFIGS: dict[str, tuple[str, bool, str]] = {
    "none": ("none", False, "CM only"),
    "lhd": ("lhd", False, "CM + LHD"),
    "deployed": (DEPLOYED_MONITOR, False, f"deployed ({DEPLOYED_MONITOR.partition(',threshold')[0]})"),
    "batched": (DEPLOYED_MONITOR, True, "deployed, patches batched (check_many)"),
}
ENGINES = ("torch", "onnx")
TARGET_S = 0.35


class BatchedLanding(EmergencyLanding):
    """The flight loop whose score walk judges every candidate of the frame in one ``monitor.check_many`` call
    (``el.monitors.patch_judge.batch_judge``), and which hashes a frame file from the bytes it decodes
    (``el.base.imageio.read_image_hashed``, no second read): the wiring ``EmergencyLanding._judge`` and ``_read``
    would take."""

    def _read(self, image: Any, info: dict[str, Any]) -> Any:
        if not isinstance(image, str | Path):
            return super()._read(image, info)
        info["path"] = str(image)
        rgb, meta, info["sha256"] = read_image_hashed(image, max_pixels=self.config.max_pixels)
        info.update(meta)  # exif_orientation, when one was applied
        info["width"], info["height"] = int(rgb.shape[1]), int(rgb.shape[0])
        return check_rgb(rgb, "image", min_size=MIN_FRAME_SIZE)

    def _judge(self, frame: Any, budget: Any) -> tuple[Any, Any, Any]:
        judge, before, after = super()._judge(frame, budget)
        if judge is None or self.walk != SCORE or not hasattr(self.monitor, "check_many"):
            return judge, before, after
        return batch_judge(self.monitor, frame.rgb, frame.candidates, self.segmenter, probs=frame.probs,
                           seed=self.config.seed), before, after


def _load(engine: str, threads: int) -> object:
    old = os.environ.get(ENGINE_ENV)
    os.environ[ENGINE_ENV] = engine
    try:
        seg = load_model(None, threads=threads)
    finally:
        if old is None:
            del os.environ[ENGINE_ENV]
        else:
            os.environ[ENGINE_ENV] = old
    if getattr(seg, "engine_name", None) != engine:
        raise SystemExit(f"engine {engine} not available (install onnxruntime; el/segmentation/weights/model.onnx)")
    return seg


def _key(d: object) -> tuple:
    return (d.action, d.selected, tuple((round(c.x, 3), round(c.y, 3)) for c in d.candidates))


def same_verdicts(a: object, b: object, tol: float = 1e-6) -> bool:
    """Whether two decisions on one frame agree: :func:`_key`, each candidate's verdict, and its score to ``tol``."""
    if _key(a) != _key(b):
        return False
    for ca, cb in zip(a.candidates, b.candidates, strict=True):
        va, vb = ca.monitor, cb.monitor
        if (va is None) != (vb is None):
            return False
        if va is not None and (va.accepted != vb.accepted or not abs(va.score - vb.score) <= tol):
            return False
    return True


def _args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="data/test", help="UAVid-layout scenes (default data/test)")
    p.add_argument("--scenes", type=int, default=10, help="frames to decide on (default 10)")
    p.add_argument("--threads", type=int, default=2, help="threads of either engine (default 2)")
    p.add_argument("--rounds", type=int, default=2, help="repeat the interleaved measure (default 2)")
    p.add_argument("--engines", nargs="+", choices=ENGINES, default=list(ENGINES), help="engines (default both)")
    p.add_argument("--configs", nargs="+", choices=list(CONFIGS), default=list(CONFIGS),
                   help=f"configurations (default all: {', '.join(CONFIGS)})")
    p.add_argument("--patch-workers", type=int, default=None,
                   help="ONNX Runtime sessions segmenting a frame's patches side by side in the batched judge "
                        "(default: one per engine thread; 1: batches of equal padded size on the one session)")
    return p.parse_args(argv)


def _systems(engines: list[str], configs: list[str], threads: int, patch_workers: int | None
             ) -> dict[tuple[str, str], EmergencyLanding]:
    segs = {e: _load(e, threads) for e in engines}
    for seg in segs.values():
        seg.patch_workers = patch_workers
    out = {}
    for e in engines:
        for name in configs:
            spec, batched, _ = CONFIGS[name]
            cls = BatchedLanding if batched else EmergencyLanding
            out[(e, name)] = cls(PipelineConfig(monitor=spec, time_budget_s=None), segmenter=segs[e])
    return out


def _measure(systems: dict, samples: list, engines: list[str], configs: list[str], rounds: int) -> tuple:
    """Latencies and segmentation times per (engine, configuration), engines and configurations interleaved, and
    the frames whose decisions differ between the engines, and between batched and per-candidate judging."""
    lat: dict[tuple[str, str], list[float]] = {k: [] for k in systems}
    seg_s: dict[tuple[str, str], list[float]] = {k: [] for k in systems}
    differ = dict.fromkeys(configs, 0)
    batch_differ = 0
    for r in range(rounds):
        for s in samples:
            decided: dict[tuple[str, str], Any] = {}
            for name in (configs if r % 2 == 0 else configs[::-1]):
                for e in (engines if r % 2 == 0 else engines[::-1]):
                    t = time.perf_counter()
                    d = decided[(e, name)] = systems[(e, name)].decide(s.image_path)
                    lat[(e, name)].append(time.perf_counter() - t)
                    seg_s[(e, name)].append(d.timings.get("segmentation_s", float("nan")))
                    if d.reason.startswith("fault"):
                        print(f"{s.key} {e} {name}: {d.reason}", file=sys.stderr)
                if r == 0 and len(engines) == 2:
                    differ[name] += _key(decided[("torch", name)]) != _key(decided[("onnx", name)])
            if r == 0 and "deployed" in configs and "batched" in configs:
                batch_differ += sum(not same_verdicts(decided[(e, "deployed")], decided[(e, "batched")])
                                    for e in engines)
    return lat, seg_s, differ, batch_differ


def main(argv: list[str] | None = None) -> int:
    args = _args(argv)
    samples = list(iter_samples(args.data))[: args.scenes]
    if not samples:
        print(f"{args.data}: no scenes (generate them with `uav-el synth`)", file=sys.stderr)
        return 2
    engines, configs = [e for e in ENGINES if e in args.engines], [c for c in CONFIGS if c in args.configs]
    systems = _systems(engines, configs, args.threads, args.patch_workers)
    for system in systems.values():  # warm up: first-call allocations, ONNX Runtime's arena
        system.decide(samples[0].image_path)
    lat, seg_s, differ, batch_differ = _measure(systems, samples, engines, configs, args.rounds)
    print(f"decision latency, {len(samples)} frames of {args.data} x {args.rounds} rounds, {args.threads} threads, "
          "engines and configurations interleaved\n")
    print("| configuration | engine | median s | p95 s | segmentation median s | decisions differing (engines) |")
    print("|---|---|---|---|---|---|")
    for name in configs:
        for e in engines:
            v = lat[(e, name)]
            print(f"| {CONFIGS[name][2]} | {e} | {statistics.median(v):.3f} | {float(np.percentile(v, 95)):.3f} | "
                  f"{statistics.median(seg_s[(e, name)]):.3f} | "
                  f"{differ[name] if e == 'onnx' and len(engines) == 2 else '-'} |")
    if "deployed" in configs and "batched" in configs:
        print(f"\nbatched vs per-candidate judging: {batch_differ} decisions differ (action, selection, positions, "
              f"verdicts, scores to 1e-6) over {len(samples)} frames x {len(engines)} engines")
    if "onnx" in engines:
        for name in ("deployed", "batched"):
            if name in configs:
                median = statistics.median(lat[("onnx", name)])
                print(f"{'PASS' if median < TARGET_S else 'FAIL'}  {CONFIGS[name][2]} under ONNX Runtime, median "
                      f"{median:.3f} s < {TARGET_S} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
