"""A fixed set of monitor inputs (softmax patches and MC-dropout samples) for the verdict-freeze test.

``paper_cases()`` rebuilds the same 48 candidates from a seed: softmax maps of a 9x9 patch, mostly safe
with forbidden pixels, near-ties and uncertain pixels of several sharpness levels, and 30 MC samples each.
The verdicts of the 21 paper configurations on them were recorded from the code before monitors had
scores (``tests/data/paper_verdicts.json``).
"""

from __future__ import annotations

import numpy as np

SIDE = 9
N_CASES = 48
N_SAMPLES = 30


def disc_mask() -> np.ndarray:
    r = np.arange(SIDE) + 0.5 - SIDE / 2
    return (r[:, None] ** 2 + r[None, :] ** 2) <= (SIDE / 2 - 0.5) ** 2


def _softmax(logits: np.ndarray, axis: int) -> np.ndarray:
    e = np.exp(logits - logits.max(axis=axis, keepdims=True))
    return (e / e.sum(axis=axis, keepdims=True)).astype(np.float32)


def paper_cases(seed: int = 18) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(softmax (8, 9, 9) float32, samples (30, 8, 9, 9) float32)]`` for ``N_CASES`` candidates."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(N_CASES):
        sharp = [0.5, 1.5, 3.0, 6.0][i % 4]
        logits = rng.normal(0.0, 0.5, (8, SIDE, SIDE))
        safe = [0, 4, 5, 6][i % 4]
        logits[safe] += 1.0 + sharp + rng.uniform(0, 2)
        if i % 4 == 1:  # a forbidden blob
            y, x = rng.integers(1, SIDE - 2, 2)
            logits[[1, 2, 3, 7][i % 4], y:y + 2, x:x + 2] += (1.0 + sharp) * rng.uniform(0.6, 1.4)
        if i % 5 == 0:  # uncertain pixels
            logits[:, :3, :] = rng.normal(0.0, 0.2, (8, 3, SIDE))
        softmax = _softmax(logits * 1.0, 0)
        if i % 7 == 0:  # an exact tie between a safe and a forbidden class at one pixel
            softmax[:, 4, 4] = 0.0
            softmax[safe, 4, 4] = 0.5
            softmax[2, 4, 4] = 0.5
        noise = rng.normal(0.0, [0.05, 0.3, 0.8][i % 3], (N_SAMPLES, 8, SIDE, SIDE))
        samples = _softmax(np.log(softmax + 1e-6)[None] + noise, 1)
        out.append((softmax, samples))
    return out
