"""How far a last-bit difference carries into the deployed decision (issue 60; docs/results.md, "Reproducibility
across machines").

Run the deployed decision on scenes under a variant of the numerics, then compare two runs stage by stage::

    .venv/bin/python benchmarks/bench_determinism.py run --data DIR --out /tmp/det/ref
    .venv/bin/python benchmarks/bench_determinism.py run --data DIR --out /tmp/det/noopt --variant ort-noopt
    .venv/bin/python benchmarks/bench_determinism.py compare /tmp/det/ref /tmp/det/noopt

Variants: ``ref``; ``ort-threads1`` (one intra-op thread); ``ort-noopt`` (ONNX Runtime's graph optimisations off:
other convolution kernels); ``cv-scalar`` (OpenCV's scalar code for the perturbation); ``noise:K`` (the network's
logits times 1 + u, u uniform within K float32 ulps). Another CPU's library paths are a ``ref`` run under their
environment variables (``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR" OPENBLAS_CORETYPE=Haswell
ATEN_CPU_CAPABILITY=avx2 OPENCV_CPU_DISABLE=AVX512F``). ``compare`` counts, over the frames of both runs: the
largest probability difference, forbidden and valid pixels that differ, frames whose CM candidates or top candidate
differ, and decisions that differ (landing place or action). The scenes: ``uav-el synth --split test --scenes 30``
(3840x2160, the release run's first 30); each perturbation seeded per scene, not by the campaign's streams.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _variant(name: str) -> None:
    """Patch the numerics of ``name`` in (before the system is built)."""
    import el.segmentation.onnx_engine as engine

    if name in ("ort-threads1", "ort-noopt"):
        real = engine.session_options

        def options(threads=None):
            o = real(1 if name == "ort-threads1" else threads)
            if name == "ort-noopt":
                o.graph_optimization_level = engine.onnxruntime().GraphOptimizationLevel.ORT_DISABLE_ALL
            return o

        engine.session_options = options
    elif name.startswith("noise:"):
        ulps, rng, run = int(name.split(":")[1]), np.random.default_rng(12345), engine.run_session

        def noisy(session, names, feeds, where):
            out = run(session, names, feeds, where)
            u = rng.uniform(-1, 1, out[0].shape).astype(np.float32) * np.float32(ulps * 2.0**-24)
            out[0] = (out[0] * (1 + u)).astype(np.float32)
            return out

        engine.run_session = noisy
    elif name not in ("ref", "cv-scalar"):
        raise SystemExit(f"unknown variant {name!r}")


def run(args: argparse.Namespace) -> None:
    _variant(args.variant)
    import cv2

    from assurance.perturbations import perturb
    from el.base.imageio import read_image
    from el.flight.pipeline import EmergencyLanding, PipelineConfig

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    system = EmergencyLanding(PipelineConfig(time_budget_s=None, hard_stop=False))
    if system.fault:
        raise SystemExit(system.fault)
    images = sorted(Path(args.data).glob("**/Images/*.png"))[: args.scenes]
    results = []
    for pert in args.perturbations:
        for i, path in enumerate(images):
            rgb = read_image(path)
            cv2.setUseOptimized(args.variant != "cv-scalar")
            rgb = perturb(rgb, pert, 3, np.random.default_rng(i))
            cv2.setUseOptimized(True)
            np.save(out / f"probs_{pert}_{i}.npy", system.segmenter.predict_frame(rgb))
            d = system.decide(rgb)
            sel = None if d.selected is None else d.candidates[d.selected]
            results.append({"pert": pert, "scene": i, "action": d.action, "reason": d.reason,
                            "selected": None if sel is None else [sel.x, sel.y],
                            "candidates": [[c.x, c.y, c.radius_px, c.hazard] for c in d.candidates],
                            "scores": [None if c.monitor is None else c.monitor.score for c in d.candidates]})
            print(pert, i, d.action, d.reason, flush=True)
    (out / "results.json").write_text(json.dumps(results))


def _valid(probs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from el.classes.labels import UAVID
    from el.geometry.config import CoreConfig
    from el.landing import candidates as cand
    from el.landing.core import _sized_unreachable_rows, reachable_working_row

    config = CoreConfig()
    _, h, w = probs.shape
    first, _ = reachable_working_row((3840, 2160), (w, h), config)
    radii = _sized_unreachable_rows(cand.row_radii(config.geometry(w, h), config.safety, config.mode), first)
    forbidden = cand.forbidden_from_probs(probs, labels=UAVID)
    return forbidden, cand.valid_pixels(forbidden, radii, mode=config.mode, min_row=first).valid


def compare(args: argparse.Namespace) -> None:
    a_dir, b_dir = Path(args.reference), Path(args.other)
    a = {(r["pert"], r["scene"]): r for r in json.loads((a_dir / "results.json").read_text())}
    b = {(r["pert"], r["scene"]): r for r in json.loads((b_dir / "results.json").read_text())}
    s = {"frames": 0, "max_prob_diff": 0.0, "forbidden_px": 0, "frames_forbidden": 0, "frames_valid": 0,
         "frames_candidates": 0, "frames_cm_top": 0, "decisions": 0}
    for key in sorted(set(a) & set(b)):
        pa, pb = (np.load(d / f"probs_{key[0]}_{key[1]}.npy") for d in (a_dir, b_dir))
        (fa, va), (fb, vb) = _valid(pa), _valid(pb)
        ca, cb = ([tuple(c[:2]) for c in r[key]["candidates"]] for r in (a, b))
        s["frames"] += 1
        s["max_prob_diff"] = max(s["max_prob_diff"], float(np.abs(pa - pb).max()))
        s["forbidden_px"] += int((fa != fb).sum())
        s["frames_forbidden"] += bool((fa != fb).any())
        s["frames_valid"] += bool((va != vb).any())
        s["frames_candidates"] += ca != cb
        s["frames_cm_top"] += ca[:1] != cb[:1]
        if (a[key]["action"], a[key]["selected"]) != (b[key]["action"], b[key]["selected"]):
            s["decisions"] += 1
            print("decision differs:", key, a[key]["selected"], "->", b[key]["selected"])
    print(json.dumps(s))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--data", required=True)
    r.add_argument("--out", required=True)
    r.add_argument("--scenes", type=int, default=30)
    r.add_argument("--variant", default="ref")
    r.add_argument("--perturbations", nargs="+", default=["none", "brightness", "fog"])
    c = sub.add_parser("compare")
    c.add_argument("reference")
    c.add_argument("other")
    args = parser.parse_args(argv)
    (run if args.command == "run" else compare)(args)


if __name__ == "__main__":
    main(sys.argv[1:])
