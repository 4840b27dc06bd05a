"""The mini-batches of a training step, drawn at both scales from ``(seed, step)`` alone, and their prefetching.

Used by :mod:`assurance.fitting.network.training` (which re-exports :func:`sample_batch` and :func:`prefetched`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import torch

from assurance.fitting.network import data as D
from assurance.fitting.network.train_config import TrainConfig

__all__ = ["prefetched", "sample_batch"]


def _to_tensor(images: list[np.ndarray]) -> torch.Tensor:
    batch = np.stack(images).astype(np.float32) / np.float32(255.0)
    return torch.from_numpy(batch).permute(0, 3, 1, 2).contiguous()


def _labels_tensor(labels: list[np.ndarray]) -> torch.Tensor:
    return torch.from_numpy(np.stack(labels).astype(np.int64))


def sample_batch(samples: list[D.Prepared], config: TrainConfig, step: int
                 ) -> tuple[tuple[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor] | None]:
    """The two mini-batches of a step (working resolution, HD or None), a pure function of ``(seed, step)``."""
    rng = np.random.default_rng([config.seed, 1, step])
    imgs, labs = [], []
    for _ in range(config.batch):
        s = samples[int(rng.integers(len(samples)))]
        img, lab = D.random_crop(s.image, s.labels, config.crop, rng, config.augment)
        imgs.append(img)
        labs.append(lab)
    working = (_to_tensor(imgs), _labels_tensor(labs))
    with_regions = [s for s in samples if len(s.regions)]
    if not config.hd_pixels or not with_regions:
        return working, None
    side = D.hd_crop_side(rng, config.hd_crop_min, config.hd_crop_max)
    imgs, labs = [], []
    for _ in range(D.hd_crop_count(side, config.hd_pixels)):
        s = with_regions[int(rng.integers(len(with_regions)))]
        k = int(rng.integers(len(s.regions)))
        img, lab = D.random_crop(s.regions[k], s.region_labels[k], side, rng, config.augment)
        imgs.append(img)
        labs.append(lab)
    return working, (_to_tensor(imgs), _labels_tensor(labs))


def prefetched(fn: Callable[[int], Any], steps: Iterable[int], *, workers: int, depth: int) -> Iterator[Any]:
    """``fn(step)`` for each step, in order, computed ``depth`` steps ahead by ``workers`` threads.

    ``fn`` must be a pure function of the step (as :func:`sample_batch` is), so the results do not
    depend on the number of workers; with ``workers < 1`` nothing runs ahead.
    """
    if workers < 1:
        yield from (fn(s) for s in steps)
        return
    pending: deque = deque()
    todo = iter(steps)
    with ThreadPoolExecutor(workers, thread_name_prefix="batches") as pool:
        try:
            for s in todo:
                pending.append(pool.submit(fn, s))
                if len(pending) > depth:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for future in pending:
                future.cancel()
