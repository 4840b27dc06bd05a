"""A fast scalar random source with the subset of ``numpy.random.Generator`` the layout uses.

City generation draws tens of thousands of single numbers; numpy's per-call overhead dominates
there, Python's Mersenne Twister does not. Seeded, so generation stays deterministic.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from typing import Any

import numpy as np


class Rand:
    """Scalar-first random numbers: ``uniform``, ``normal``, ``random``, ``integers``, ``choice``, ``poisson``."""

    def __init__(self, seed: int) -> None:
        self._r = random.Random(seed)

    def random(self, size: int | None = None) -> Any:
        if size is None:
            return self._r.random()
        return np.array([self._r.random() for _ in range(size)])

    def uniform(self, low: float = 0.0, high: float = 1.0, size: int | None = None) -> Any:
        if size is None:
            return low + (high - low) * self._r.random()
        return np.array([low + (high - low) * self._r.random() for _ in range(size)])

    def normal(self, loc: float = 0.0, scale: float = 1.0, size: int | None = None) -> Any:
        if size is None:
            return self._r.gauss(loc, scale)
        return np.array([self._r.gauss(loc, scale) for _ in range(size)])

    def integers(self, low: int, high: int | None = None) -> int:
        """An integer in [low, high) (or [0, low) with one argument)."""
        if high is None:
            low, high = 0, low
        return self._r.randrange(int(low), int(high))

    def choice(self, a: int | Sequence[Any], p: Sequence[float] | np.ndarray | None = None) -> Any:
        seq = range(a) if isinstance(a, int) else a
        if p is None:
            return seq[self._r.randrange(len(seq))]
        return self._r.choices(seq, weights=list(p))[0]

    def poisson(self, lam: float) -> int:
        if lam <= 0:
            return 0
        if lam > 30:
            return max(0, round(self._r.gauss(lam, math.sqrt(lam))))
        limit, k, prod = math.exp(-lam), 0, self._r.random()
        while prod > limit:
            k += 1
            prod *= self._r.random()
        return k
