"""Training and evaluation data for the segmentation network, at the two scales it meets in use.

- **Working resolution**: the frame resized to ``working_size`` with ``cv2.INTER_AREA`` (exactly as
  :meth:`Segmenter.predict_frame` does), labels brought down by area-majority (the class covering the
  largest share of each working pixel; ties go to the lower class id).
- **HD patches**: full-resolution square crops (the LHD monitor's view around a candidate). For
  training, a few seeded full-resolution regions per image are kept, from which random crops are
  cut; for evaluation, a fixed, seeded set of square patches per image in the reachable rows.

Decoding 4K PNGs dominates, so :func:`load_dataset` keeps each prepared sample in a cache folder as an
uncompressed ``.npz`` named by the SHA-256 of its image and label files and the preparation
parameters: a changed file or parameter is a cache miss, never a stale hit.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from el.segmentation.protocol import EvalProtocol

import hashlib
import io
import math
import os
import zlib
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from assurance.dataio.layouts import iter_samples, read_sample_labels
from assurance.dataio.uavid import DataError, Sample, read_image
from assurance.files import atomic_write_bytes
from el.base.hashing import sha256_file
from el.classes.labels import NUM_CLASSES, UAVID
from el.geometry.camera import NUM_STRIPES, UNREACHABLE_STRIPES, working_size

CACHE_VERSION = 1

Progress = Callable[..., Iterable]


TRAINING_LABELS = UAVID
"""The classes the project's own network is trained to segment (its training data is in UAVid's palette)."""


@dataclass(frozen=True, kw_only=True)
class PrepParams:
    """How a sample is prepared (part of every cache key).

    ``regions``/``region_size``: full-resolution square regions kept per image (0 for none).
    ``seed``: where the regions lie (with the sample's key).
    """

    working_width: int = 1024
    regions: int = 4
    region_size: int = 512
    seed: int = 0

    def __post_init__(self) -> None:
        if self.working_width < 16:
            raise ValueError(f"working_width must be >= 16, got {self.working_width!r}")
        if self.regions < 0:
            raise ValueError(f"regions must be >= 0, got {self.regions!r}")
        if self.region_size < 16:
            raise ValueError(f"region_size must be >= 16, got {self.region_size!r}")

    def key(self) -> str:
        text = repr((CACHE_VERSION, sorted(asdict(self).items())))
        return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass
class Prepared:
    """One sample at both scales: working-resolution frame and labels, full-resolution regions."""

    key: str
    image: np.ndarray  # (h, w, 3) uint8, working resolution
    labels: np.ndarray  # (h, w) uint8 class ids, working resolution
    regions: np.ndarray  # (K, s, s, 3) uint8, full resolution
    region_labels: np.ndarray  # (K, s, s) uint8
    full_size: tuple[int, int]  # (W, H) of the original


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/uav-el/segmentation`` (``~/.cache/...`` when the variable is unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "uav-el" / "segmentation"


# -- hashing ------------------------------------------------------------------------------------
def _file_sha256(path: Path) -> str:
    return sha256_file(path)


@dataclass(frozen=True)
class Manifest:
    """The samples of a dataset folder and the SHA-256 of each image and label file."""

    root: Path
    samples: tuple[Sample, ...]
    hashes: tuple[tuple[str, str], ...]  # (image sha256, label sha256) per sample

    @property
    def sha256(self) -> str:
        """SHA-256 over the sorted lines ``key image_sha label_sha``: the dataset's identity."""
        lines = sorted(f"{s.key} {hi} {hl}\n" for s, (hi, hl) in zip(self.samples, self.hashes, strict=True))
        return hashlib.sha256("".join(lines).encode()).hexdigest()

    def describe(self) -> dict:
        return {"path": str(self.root), "images": len(self.samples), "sha256": self.sha256}


def dataset_manifest(root: str | Path, *, threads: int = 2) -> Manifest:
    """List a UAVid-layout folder (labels required) and hash its files. DataError if empty or broken."""
    samples = tuple(iter_samples(root, require_labels=True))  # any layout (a DataSpec keeps its patterns)
    root = Path(root)
    if not samples:
        raise DataError(f"{root}: no images found")
    paths = [p for s in samples for p in (s.image_path, s.label_path)]
    with ThreadPoolExecutor(max(1, threads)) as pool:
        digests = list(pool.map(_file_sha256, paths))
    hashes = tuple((digests[2 * i], digests[2 * i + 1]) for i in range(len(samples)))
    return Manifest(root, samples, hashes)


# -- preparation --------------------------------------------------------------------------------
def downsample_labels(ids: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Class ids (H, W) -> (h, w) by area-majority: each output pixel takes the class that covers
    the largest share of its footprint (``size`` is (w, h) as for cv2)."""
    if (ids.shape[1], ids.shape[0]) == tuple(size):
        return ids.copy()
    cover = np.stack([cv2.resize((ids == k).astype(np.float32), size, interpolation=cv2.INTER_AREA)
                      for k in range(NUM_CLASSES)])
    return cover.argmax(axis=0).astype(np.uint8)


def _key_seed(key: str, seed: int) -> list[int]:
    return [int(seed), zlib.crc32(key.encode())]


def patch_positions(key: str, width: int, height: int, *, count: int, size: int, seed: int
                    ) -> tuple[int, list[tuple[int, int]]]:
    """Seeded top-left corners (x, y) of ``count`` square patches in the reachable rows of an image.

    The side is clipped to the image; patches start below the unreachable top stripes where the image
    is tall enough. Returns ``(side, corners)``.
    """
    side = int(min(size, width, height))
    rng = np.random.default_rng(_key_seed(key, seed))
    top = int(round(height * UNREACHABLE_STRIPES / NUM_STRIPES))
    top = min(top, height - side)
    corners = [(int(rng.integers(0, width - side + 1)), int(rng.integers(top, height - side + 1)))
               for _ in range(count)]
    return side, corners


def prepare_sample(key: str, image: np.ndarray, labels: np.ndarray, params: PrepParams) -> Prepared:
    """Both scales of one full-resolution image and its class ids."""
    if image.shape[:2] != labels.shape:
        raise DataError(f"{key}: image {image.shape[1]}x{image.shape[0]} and labels "
                        f"{labels.shape[1]}x{labels.shape[0]} differ in size")
    height, width = labels.shape
    size = working_size(width, height, params.working_width)
    wr_image = image if (width, height) == size else cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    wr_labels = downsample_labels(labels, size)
    side, corners = patch_positions(key, width, height, count=params.regions, size=params.region_size,
                                    seed=params.seed)
    regions = np.stack([image[y:y + side, x:x + side] for x, y in corners]) if corners else \
        np.zeros((0, side, side, 3), np.uint8)
    region_labels = np.stack([labels[y:y + side, x:x + side] for x, y in corners]) if corners else \
        np.zeros((0, side, side), np.uint8)
    return Prepared(key, np.ascontiguousarray(wr_image), wr_labels, regions, region_labels, (width, height))


def _cache_file(cache_dir: Path, hashes: tuple[str, str], params: PrepParams) -> Path:
    digest = hashlib.sha256(f"{hashes[0]} {hashes[1]}".encode()).hexdigest()[:24]
    return cache_dir / f"{digest}-{params.key()}.npz"


def _load_one(sample: Sample, hashes: tuple[str, str], params: PrepParams, cache_dir: Path | None) -> Prepared:
    path = _cache_file(cache_dir, hashes, params) if cache_dir is not None else None
    if path is not None and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                return Prepared(sample.key, z["image"], z["labels"], z["regions"], z["region_labels"],
                                (int(z["full_size"][0]), int(z["full_size"][1])))
        except (OSError, KeyError, ValueError, zlib.error):
            path.unlink(missing_ok=True)  # a broken cache entry is rebuilt
    if sample.label_path is None:
        raise DataError(f"{sample.image_path}: no label file (training and evaluation need labels)")
    ids = read_sample_labels(sample, TRAINING_LABELS)
    prep = prepare_sample(sample.key, read_image(sample.image_path), ids, params)
    if path is not None:
        buf = io.BytesIO()
        np.savez(buf, image=prep.image, labels=prep.labels, regions=prep.regions,
                 region_labels=prep.region_labels, full_size=np.array(prep.full_size))
        atomic_write_bytes(path, buf.getvalue())
    return prep


def load_dataset(manifest: Manifest, params: PrepParams, *, cache_dir: str | Path | None = None,
                 threads: int = 2, progress: Progress | None = None) -> list[Prepared]:
    """Prepare every sample of a dataset (from the cache where possible), in manifest order."""
    cdir = Path(cache_dir) if cache_dir is not None else None
    if cdir is not None:
        cdir.mkdir(parents=True, exist_ok=True)

    def job(i: int) -> Prepared:
        return _load_one(manifest.samples[i], manifest.hashes[i], params, cdir)

    with ThreadPoolExecutor(max(1, threads)) as pool:
        results: Iterator[Prepared] = pool.map(job, range(len(manifest.samples)))
        if progress is not None:
            results = iter(progress(results, total=len(manifest.samples), desc=f"prepare {manifest.root.name}"))
        return list(results)


def class_frequencies(samples: Iterable[Prepared]) -> np.ndarray:
    """Share of each class among working-resolution and region label pixels, shape (8,)."""
    counts = np.zeros(NUM_CLASSES, np.float64)
    for s in samples:
        counts += np.bincount(s.labels.ravel(), minlength=NUM_CLASSES)[:NUM_CLASSES]
        if s.region_labels.size:
            counts += np.bincount(s.region_labels.ravel(), minlength=NUM_CLASSES)[:NUM_CLASSES]
    total = counts.sum()
    return counts / total if total else counts


def class_weights(freq: np.ndarray, *, max_ratio: float = 50.0) -> np.ndarray:
    """Inverse-square-root frequency weights, normalised to a mean weight of 1 per pixel.

    Classes absent from the data get the largest weight (they contribute no pixels anyway); the
    ratio between the largest and the smallest weight is capped at ``max_ratio``.
    """
    freq = np.asarray(freq, np.float64)
    present = freq > 0
    if not present.any():
        return np.ones(NUM_CLASSES, np.float32)
    w = np.zeros_like(freq)
    w[present] = 1.0 / np.sqrt(freq[present])
    w[present] = np.minimum(w[present], w[present].min() * max_ratio)
    w[~present] = w[present].max()
    w /= float((freq * w).sum())
    return w.astype(np.float32)


# -- augmentation and batches -------------------------------------------------------------------
# Used in training: horizontal flip, scale jitter, small hue and saturation jitter, Gaussian noise.
# Deliberately NOT used (they are the evaluation perturbations): brightness shifts, fog, motion blur,
# shifted pixel rows, dead (zeroed) rows.
AUGMENTATIONS = ("hflip", "scale_jitter", "hue_jitter", "saturation_jitter", "gaussian_noise")


@dataclass(frozen=True, kw_only=True)
class AugmentParams:
    scale_jitter: float = 0.15  # crop side scaled by a factor in [1 - j, 1 + j]
    hue_deg: float = 5.0  # hue shifted by up to +-hue_deg degrees
    saturation: float = 0.1  # saturation scaled by a factor in [1 - s, 1 + s]
    noise_std: float = 3.0  # Gaussian noise with a std drawn in [0, noise_std] grey levels

    def __post_init__(self) -> None:
        if not (0 <= self.scale_jitter < 0.5):
            raise ValueError(f"scale_jitter must lie in [0, 0.5), got {self.scale_jitter!r}")
        if not (0 <= self.hue_deg <= 30 and 0 <= self.saturation < 1 and 0 <= self.noise_std <= 20):
            raise ValueError("hue_deg must lie in [0, 30], saturation in [0, 1), noise_std in [0, 20]")


def _colour_jitter(img: np.ndarray, rng: np.random.Generator, aug: AugmentParams) -> np.ndarray:
    if aug.hue_deg > 0 or aug.saturation > 0:
        hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV).astype(np.float32)
        hsv[..., 0] = np.mod(hsv[..., 0] + rng.uniform(-aug.hue_deg, aug.hue_deg) / 2.0, 180.0)
        hsv[..., 1] = np.clip(hsv[..., 1] * rng.uniform(1 - aug.saturation, 1 + aug.saturation), 0, 255)
        img = cv2.cvtColor(hsv.round().astype(np.uint8), cv2.COLOR_HSV2RGB)  # V (brightness) untouched
    if aug.noise_std > 0:
        std = rng.uniform(0, aug.noise_std)
        img = np.clip(img.astype(np.float32) + rng.normal(0, std, img.shape).astype(np.float32), 0, 255)
        img = img.round().astype(np.uint8)
    return img


def random_crop(image: np.ndarray, labels: np.ndarray, side: int, rng: np.random.Generator,
                aug: AugmentParams) -> tuple[np.ndarray, np.ndarray]:
    """A random square crop of ``side`` px (after scale jitter, resized back), flipped and colour-jittered."""
    h, w = labels.shape
    scale = rng.uniform(1 - aug.scale_jitter, 1 + aug.scale_jitter)
    src = int(min(max(8, round(side * scale)), h, w))
    y = int(rng.integers(0, h - src + 1))
    x = int(rng.integers(0, w - src + 1))
    img = image[y:y + src, x:x + src]
    lab = labels[y:y + src, x:x + src]
    if src != side:
        img = cv2.resize(img, (side, side), interpolation=cv2.INTER_AREA if src > side else cv2.INTER_LINEAR)
        lab = cv2.resize(lab, (side, side), interpolation=cv2.INTER_NEAREST)
    if rng.random() < 0.5:
        img, lab = img[:, ::-1], lab[:, ::-1]
    return _colour_jitter(np.ascontiguousarray(img), rng, aug), np.ascontiguousarray(lab)


def hd_crop_side(rng: np.random.Generator, lo: int, hi: int, step: int = 32) -> int:
    """A crop side drawn uniformly from lo, lo + step, ..., hi."""
    choices = np.arange(lo, hi + 1, step)
    return int(choices[rng.integers(0, len(choices))]) if len(choices) else int(lo)


def hd_crop_count(side: int, pixel_budget: int) -> int:
    """How many HD crops of this side fit a per-step pixel budget (at least one)."""
    return max(1, int(math.floor(pixel_budget / float(side * side) + 0.5)))


def protocol_prep(protocol: EvalProtocol) -> PrepParams:
    """How the samples a model card's evaluation protocol describes are prepared."""
    return PrepParams(working_width=protocol.working_width, regions=protocol.hd_patches,
                      region_size=protocol.hd_patch_size, seed=protocol.seed)
