"""Benchmark of each monitor's cost per candidate, from what the segmentation pass computed, against LHD.

    .venv/bin/python benchmarks/bench_monitors.py [--candidates 200] [--radius 60] [--seed 0]

Builds a softened urban-like softmax for a 3840x2160 frame's HD patch around a candidate of ``--radius`` pixels
and the frame's softmax at the working resolution (1024x576), then times, per candidate, what each monitor adds
to the shared segmentation (which every monitor needs and which is not timed here):

- ``features``: what it computes from the softmax before scoring (the disc's pixels for the softmax family; the
  candidate feature vector for the fitted detectors and the learned monitor);
- ``score``: its reduction and judgement (``reduce`` + ``judge``).

Prints a table: median microseconds per candidate and the ratio to LHD's total. Not a unit test: numbers depend
on the machine. The fitted detectors use records fitted here on random feature vectors (their cost does not
depend on what they were fitted on); the learned monitor uses the shipped model.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from el.base.decision import Candidate
from el.classes.labels import UAVID
from el.monitors import CandidateContext, build_monitor, extract_patch
from el.monitors.learned import DEFAULT_MODEL, base_features

SPECS = ("lhd", "lhd+ch:tau=0.25", "msp", "entropy", "energy", "odin", "doctor", "learned")
FITTED = ("mahalanobis", "gmm", "outside_box")
W_FULL, H_FULL, W_WORK, H_WORK = 3840, 2160, 1024, 576


class Stub:
    """Stands for the network the records are bound to (``weights_sha256``); never segments."""

    def __init__(self, sha: str) -> None:
        self.weights_sha256 = sha


def softmax(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """A (8, h, w) float32 softmax: blocks of one class, softened at random (mostly safe classes)."""
    h, w = shape
    ids = rng.choice([1, 4, 5, 5, 5, 6], size=(max(1, h // 16) + 1, max(1, w // 16) + 1))
    ids = np.kron(ids, np.ones((16, 16), np.int64))[:h, :w]
    logits = rng.normal(0.0, 1.0, (8, h, w)) + 4.0 * (np.arange(8)[:, None, None] == ids[None])
    e = np.exp(logits - logits.max(axis=0, keepdims=True))
    return (e / e.sum(axis=0, keepdims=True)).astype(np.float32)


def fitted_records(folder: Path, sha: str, rng: np.random.Generator) -> list[str]:
    """Records of the fitted families on random feature vectors, bound to the stub network: their specs."""
    from assurance.fitting.detectors import detector_document, fit_detector_body
    from assurance.fitting.learned_monitor import CandidateSet

    d = len(base_features(UAVID))
    x = rng.normal(size=(400, d))
    y = rng.random(400) < 0.3
    part = CandidateSet(x, y, np.zeros(400, np.int64), "0" * 64, 1)
    specs = []
    for family in FITTED:
        path = folder / f"{family}.json"
        body = fit_detector_body(family, part, part, labels=UAVID, weights={"sha256": sha})
        path.write_text(json.dumps(detector_document(body)))
        specs.append(f"{family}:model={path}")
    return specs


def timed(fn: Any, *args: Any, **kwargs: Any) -> tuple[Any, float]:
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def bench(specs: list[str], n: int, radius: float, rng: np.random.Generator,
          sha: str) -> list[tuple[str, float, float]]:
    hd = np.zeros((H_FULL, W_FULL, 3), np.uint8)
    frame = softmax(rng, (H_WORK, W_WORK))
    seg = Stub(sha)
    cands = [Candidate(k, float(rng.uniform(radius * 2, W_FULL - radius * 2)),
                       float(rng.uniform(radius * 2, H_FULL - radius * 2)), radius, 0.1, 0.1, 0.0) for k in range(n)]
    patches = [extract_patch(hd, c, margin=0.25) for c in cands]
    probs = [softmax(rng, p.shape) for p in patches]
    rows = []
    for spec in specs:
        m = build_monitor(spec, labels=UAVID)
        feat_t, score_t = [], []
        for c, p, pr in zip(cands, patches, probs, strict=True):
            if hasattr(m, "model") or hasattr(m, "record"):  # the learned monitor and the fitted detectors
                (feats, mask), tf = timed(m.softmax_features, pr, p, seg, context=CandidateContext(c, frame,
                                                                                                  (W_FULL, H_FULL)))
            else:
                (feats, mask), tf = (pr, p.disc_mask), 0.0
            red, tr = timed(m.reduce, feats, mask)
            _, tj = timed(m.judge, red)
            feat_t.append(tf)
            score_t.append(tr + tj)
        rows.append((m.name.split(":model=")[0], statistics.median(feat_t) * 1e6, statistics.median(score_t) * 1e6))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, default=200)
    ap.add_argument("--radius", type=float, default=60.0, help="candidate radius in full-resolution pixels")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    sha = json.loads(Path(DEFAULT_MODEL).read_text())["body"]["weights"]["sha256"]  # the shipped model's network
    with tempfile.TemporaryDirectory() as tmp:
        rows = bench([*SPECS, *fitted_records(Path(tmp), sha, rng)], a.candidates, a.radius, rng, sha)
    base = rows[0][1] + rows[0][2]
    print(f"per candidate, median of {a.candidates} (radius {a.radius:g} px, HD patch {2 * 1.25 * a.radius:.0f} px "
          "wide); the shared segmentation is not included")
    print(f"{'monitor':<18}{'features us':>13}{'score us':>11}{'total us':>11}{'x LHD':>8}")
    for name, f, s in rows:
        print(f"{name:<18}{f:>13.1f}{s:>11.1f}{f + s:>11.1f}{(f + s) / base:>8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
