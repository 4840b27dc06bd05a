"""Shared test doubles: a perfect segmenter on colour-coded label images, and a fake clock."""

from __future__ import annotations

import contextlib
import signal
from pathlib import Path

import numpy as np

from el.classes.labels import NUM_CLASSES, PALETTE, UAVID, ids_to_colors
from el.geometry.camera import working_size
from el.landing.core import probs_from_labels
from el.segmentation.model import ArchConfig

TINY_ARCH = ArchConfig(widths=(8, 8, 16), ms_channels=8, decoder_channels=8)
"""The tiny network of the segmentation and training tests (fast on one thread)."""


def nearest_class(rgb: np.ndarray) -> np.ndarray:
    """Class ids of the nearest label colour per pixel (exact on clean label images)."""
    d = ((rgb[..., None, :].astype(np.int32) - PALETTE.astype(np.int32)) ** 2).sum(-1)
    return d.argmin(-1).astype(np.uint8)


class OracleSegmenter:
    """Segments a colour-coded label image perfectly (colour -> class), at frame and patch level.

    MC dropout returns ``n`` copies of the one-hot (no uncertainty). Fault knobs let tests break it. It
    reports a weights hash of its own, as a real network does, so records fitted on it are bound to it.
    """

    weights_sha256 = "0e" * 32

    def __init__(self, working_width: int, *, nan: bool = False) -> None:
        self.working_width = working_width
        self.nan = nan
        self.patch_calls = 0

    def _onehot(self, ids: np.ndarray) -> np.ndarray:
        probs = np.zeros((NUM_CLASSES, *ids.shape), np.float32)
        np.put_along_axis(probs, ids[None].astype(np.intp), 1.0, axis=0)
        if self.nan:
            probs[:] = np.nan
        return probs

    def predict_frame(self, rgb: np.ndarray) -> np.ndarray:
        ids = nearest_class(rgb)
        probs = probs_from_labels(ids, working_size(rgb.shape[1], rgb.shape[0], self.working_width), labels=UAVID)
        if self.nan:
            probs[:] = np.nan
        return probs

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        self.patch_calls += 1
        return self._onehot(nearest_class(rgb_patch))

    def mc_dropout(self, rgb_patch: np.ndarray, n: int, keep_prob: float, seed: int) -> np.ndarray:
        """Noisy copies of the one-hot, drawn sample by sample (prefix-consistent for a seed)."""
        base = self.predict_patch(rgb_patch)
        rng = np.random.default_rng(seed)
        out = np.empty((n, *base.shape), np.float32)
        for i in range(n):
            noisy = base + (1.0 - keep_prob) * rng.random(base.shape, dtype=np.float32)
            out[i] = noisy / noisy.sum(axis=0, keepdims=True)
        return out


class FakeClock:
    """A clock that advances by ``step`` seconds at each reading (and can jump)."""

    def __init__(self, step: float = 0.0, start: float = 0.0) -> None:
        self.t, self.step = start, step

    def __call__(self) -> float:
        self.t += self.step
        return self.t


def scene_ids(width: int = 256, height: int = 144, *, road_col: int | None = None, seed: int = 0) -> np.ndarray:
    """A small label map: low vegetation with a vertical road, a building block and a few trees."""
    rng = np.random.default_rng(seed)
    ids = np.full((height, width), 5, np.uint8)  # low vegetation
    rc = road_col if road_col is not None else width // 3
    ids[:, rc : rc + max(2, width // 40)] = 2  # road
    bx = int(rng.integers(width // 2, width - width // 6))
    ids[: height // 3, bx : bx + width // 8] = 1  # building
    for _ in range(4):
        y, x = int(rng.integers(height // 3, height - 5)), int(rng.integers(0, width - 5))
        ids[y : y + 4, x : x + 4] = 4  # tree
    return ids


def write_textured_scenes(root: Path, seeds, width: int = 128, height: int = 72, sequence: str = "seq00") -> Path:
    """One UAVid-layout sequence under ``root``: a ``scene_ids`` scene per seed with seeded colour noise as
    texture (frames for out-of-domain gates, which need some variance)."""
    from assurance.dataio.uavid import write_sample

    for i, seed in enumerate(seeds):
        ids = scene_ids(width, height, seed=seed, road_col=10 + (7 * seed) % 90)
        rgb = ids_to_colors(ids).astype(np.int16)
        rgb += np.random.default_rng(seed).integers(-12, 13, rgb.shape, dtype=np.int16)  # texture
        write_sample(root, sequence, f"{i:06d}", np.clip(rgb, 0, 255).astype(np.uint8), ids, labels=UAVID)
    return root


def scene_image(ids: np.ndarray) -> np.ndarray:
    """The colour-coded label image that OracleSegmenter reads back."""
    return ids_to_colors(ids)


def reseal_shard(run, name: str) -> None:
    """Re-hash a shard edited by a test (SHA256SUMS and the run's index), as if the campaign had written it
    that way: for tests that need a run with odd readouts that still verifies."""
    from pathlib import Path

    from assurance.fault_injection.case import reseal_shard as reseal

    reseal(Path(run), name)


def install_distribution(site: Path, module: Path, group: str, entry: str) -> None:
    """Lay ``module`` out in folder ``site`` as an installed distribution whose entry point ``entry``
    (``name = module:attr``) is in ``group``; the caller puts ``site`` on ``sys.path``."""
    import shutil

    site.mkdir(parents=True, exist_ok=True)
    shutil.copy(module, site / module.name)
    info = site / f"{module.stem}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module.stem.replace('_', '-')}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{group}]\n{entry}\n")


def allow_weaker_registry(monkeypatch) -> None:
    """Let the gate accept a registry weaker than the system's (``lenient_registry``), for tests of other gate
    behaviour; the weakening check itself is tested in tests/test_registry_weakening.py."""
    monkeypatch.setattr("assurance.evidence.context.weakening_problems", lambda registry, system=None: [])


def lenient_registry(folder: Path) -> Path:
    """A copy of the shipped registry that declares every requirement undecidable on a run smaller than the
    release (``size_limited``): for tests of other gate behaviour on partial test sessions (the gate refuses it as
    weaker than the system's unless ``allow_weaker_registry``)."""
    import re

    from assurance.requirements import default_registry_path

    text = default_registry_path().read_text(encoding="utf-8")
    ids = ", ".join(re.findall(r"^  - id: (EL-R\d+)$", text, flags=re.M))
    start = text.index("  size_limited: [")
    end = text.index("]", start) + 1
    path = Path(folder) / "lenient-registry.yaml"
    path.write_text(text[:start] + f"  size_limited: [{ids}]" + text[end:], encoding="utf-8")
    return path


def bench_system(folder: Path) -> Path:
    """``folder/uav-el.toml``: the embedded default but for a declared domain that admits the tests' small frames
    (64-7680 x 36-4320 px; the embedded default declares only its camera's 4K frames). A command run in
    ``folder`` (``monkeypatch.chdir``) or given ``--system`` with it decides those frames instead of refusing them
    as ``outside_odd``."""
    from assurance.fault_injection.case import write_small_frame_system

    return write_small_frame_system(folder)


@contextlib.contextmanager
def within_seconds(seconds: int):
    """Fail (instead of hanging the session) when the block runs longer than ``seconds``."""
    def expire(signum, frame):
        raise TimeoutError(f"blocked for more than {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


class TappedOracle(OracleSegmenter):
    """A perfect segmentation (so that frames have candidates to judge and land on) whose frame pass also runs
    ``seg`` (a tiny network), returning its frame statistics for the frame gate (``predict_frame(rgb,
    stats=True)``); it reports ``weights_sha256`` as the network's hash."""

    frame_stats = True

    def __init__(self, seg, working_width: int, weights_sha256: str) -> None:
        super().__init__(working_width)
        self.seg, self.weights_sha256 = seg, weights_sha256

    def predict_frame(self, rgb, *, stats=False):
        from el.segmentation.frame_tap import FramePass

        found = self.seg.predict_frame(rgb, stats=stats)
        probs = super().predict_frame(rgb)
        return FramePass(probs, found.stats) if stats else probs


def sleep_a_minute(*args: object, **kwargs: object) -> None:
    """Stands in for work that does not end (picklable: a spawned child imports it from here)."""
    import time

    time.sleep(60)
