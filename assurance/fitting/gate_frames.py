"""The frames of the frame-gate study, each tapped once by the frame's own segmentation pass and kept
in one cache (``taps.npz``): the gate variants are then fitted and measured on the cached features in seconds.

Sets (the test split is never read): ``train`` (every training scene clean, under each in-domain perturbation at a
severity drawn from 1-3, seeded per scene, and under each at severity 3), ``val_sev3`` (every validation scene
clean and under each perturbation at severity 3), ``val_sev45`` (the last validation scenes under each
perturbation at severities 4 and 5), the ``ood_*`` folders of the data root (the synthetic city at poses outside the
declared domain, made with ``uav-el synth --heights/--pitches``, or at another frame size), noise, constant frames,
the scikit-image sample photographs, another procedural world (natural terrain: sea, coast, forest, rock; no city)
and the city at night. The generated sets are made at the study's frame size, the deployed camera's (3840x2160):
the gate must judge frames as the camera delivers them, area-downscaled to the network's working width.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from assurance.dataio.layouts import DataSpec, iter_samples
from assurance.dataio.uavid import read_image
from assurance.files import atomic_write_bytes
from assurance.perturbations import perturb
from assurance.progress import progress
from assurance.system.build import DEFAULT_IMAGE_SIZE
from el.segmentation.contract import segment_frame
from el.segmentation.factory import load_model

IN_DOMAIN = ("none", "brightness", "fog", "motion_blur", "shifted_pixels", "pixel_trap")
SIZE = DEFAULT_IMAGE_SIZE  # the deployed camera's frame: the release and test scenes' size
PHOTOS = ("astronaut", "chelsea", "coffee", "rocket", "hubble_deep_field", "retina", "brick", "grass", "gravel",
          "camera")  # scikit-image 0.26 package data: public domain or CC0 (each function's docstring says)
SEV45_SCENES = 20


def fit16x9(rgb: np.ndarray, size: tuple[int, int] = SIZE) -> np.ndarray:
    """Centre-crop to 16:9 and resize to ``size``: the gate judges content, not the frame's shape."""
    h, w = rgb.shape[:2]
    if w / h > 16 / 9:
        c = round(h * 16 / 9)
        rgb = rgb[:, (w - c) // 2:(w - c) // 2 + c]
    else:
        c = round(w * 9 / 16)
        rgb = rgb[(h - c) // 2:(h - c) // 2 + c]
    small = rgb.shape[1] < size[0]
    return cv2.resize(np.ascontiguousarray(rgb), size, interpolation=cv2.INTER_CUBIC if small else cv2.INTER_AREA)


def scene_images(data: str | Path | DataSpec, first: int = 0, count: int | None = None) -> list[Path]:
    samples = list(iter_samples(data, require_labels=False))[first:None if count is None else first + count]
    return [s.image_path for s in samples]


def perturbed(rgb: np.ndarray, name: str, severity: int, seed: Any) -> np.ndarray:
    return rgb if name == "none" else perturb(rgb, name, severity, np.random.default_rng(seed))


def in_domain(levels: Sequence[tuple[str, int]] | None = None) -> tuple[tuple[str, int], ...]:
    """The in-domain perturbations as (name, top severity), ``none`` first: ``levels`` (a system's declared ones,
    ``assurance.campaign.perturbation_plan.fit_levels``), else the shipped gate's :data:`IN_DOMAIN` at 3."""
    if levels is None:
        return tuple((name, 3) for name in IN_DOMAIN)
    rest = tuple((str(n), int(s)) for n, s in levels if n != "none")
    return (("none", 3), *rest)


def training_frames(paths: list[Path], seed: int = 1, levels: Sequence[tuple[str, int]] | None = None
                    ) -> Iterator[tuple[int, str, np.ndarray]]:
    """Every training scene clean, under each in-domain perturbation (:func:`in_domain` of ``levels``) at a
    severity in 1-3 (seeded per scene; at most its top), and under each at its top, the declared maximum (3: 11
    frames a scene for the shipped six)."""
    domain = in_domain(levels)
    for i, path in enumerate(paths):
        rgb = read_image(path)
        sev = np.random.default_rng([seed, i]).integers(1, 4, len(domain))
        for (name, top), drawn in zip(domain, sev, strict=True):
            s = min(int(drawn), top)
            yield i, f"{name}:{0 if name == 'none' else s}", perturbed(rgb, name, s, [seed, i, s])
        for name, top in domain[1:]:
            yield i, f"{name}:{top}", perturbed(rgb, name, top, [seed + 4, i, top])


def validation_frames(paths: list[tuple[int, Path]], severities: tuple[int, ...], seed: int = 3,
                      levels: Sequence[tuple[str, int]] | None = None) -> Iterator[tuple[int, str, np.ndarray]]:
    """Every (index, validation scene) under each perturbation at each of ``severities`` (clean once, when 3 is
    asked); with ``levels`` (:func:`in_domain`), a system's declared perturbations, each at most at its top."""
    names = IN_DOMAIN if levels is None else tuple(n for n, _ in in_domain(levels))
    tops = dict(in_domain(levels)) if levels is not None else {}
    for i, path in paths:
        rgb = read_image(path)
        for name in names:
            for s in dict.fromkeys(min(level, tops.get(name, level)) for level in severities):
                if name == "none" and s != 3:
                    continue
                yield i, f"{name}:{0 if name == 'none' else s}", perturbed(rgb, name, s, [seed, i, s])


def noise_frames(seed: int = 0, n: int = 10, size: tuple[int, int] = SIZE) -> list[np.ndarray]:
    """Uniform noise, then Gaussian noise around grey."""
    rng = np.random.default_rng(seed)
    w, h = size
    noise = [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(n // 2)]
    return noise + [np.clip(rng.normal(128, 40, (h, w, 3)), 0, 255).astype(np.uint8) for _ in range(n - n // 2)]


def constant_frames(n: int = 10, size: tuple[int, int] = SIZE) -> list[np.ndarray]:
    """Constant frames: black to white, grey levels and colours."""
    w, h = size
    return [np.full((h, w, 3), (int(v), int(255 - v), int(v // 2)) if i % 2 else int(v), np.uint8)
            for i, v in enumerate(np.linspace(0, 255, n))]


def photos(size: tuple[int, int] = SIZE) -> list[np.ndarray]:
    import skimage.data

    out = []
    for name in PHOTOS:
        img = getattr(skimage.data, name)()
        img = np.repeat(img[..., None], 3, axis=2) if img.ndim == 2 else img[..., :3]
        out.append(fit16x9(img.astype(np.uint8), size))
    return out


WORLD_PALETTE = np.array([[18, 45, 92], [40, 96, 140], [205, 190, 140], [96, 140, 60], [34, 80, 34],
                          [120, 110, 100], [235, 235, 240]], np.float32)  # deep sea .. snow
WORLD_LEVELS = np.array([0.0, 0.35, 0.42, 0.47, 0.6, 0.75, 0.88, 1.0], np.float32)


def other_world(seed: int = 0, n: int = 10, size: tuple[int, int] = SIZE) -> list[np.ndarray]:
    """Another procedural world: natural terrain (sea, shore, fields, forest, rock, snow) from fractal noise,
    hill-shaded, with fine texture; no street, car or building. The network never saw such a world."""
    rng = np.random.default_rng([seed, 77])
    w, h = size
    out = []
    for _ in range(n):
        height = np.zeros((h // 4, w // 4), np.float32)
        for octave in range(6):  # fractal noise: coarse grids upsampled, halving the amplitude per octave
            cells = 3 * 2 ** octave
            grid = rng.random((max(2, cells * h // w), cells)).astype(np.float32)
            height += cv2.resize(grid, (w // 4, h // 4), interpolation=cv2.INTER_CUBIC) / 2 ** octave
        height = (height - height.min()) / max(float(np.ptp(height)), 1e-6)
        band = np.clip(np.searchsorted(WORLD_LEVELS, height, side="right") - 1, 0, len(WORLD_PALETTE) - 1)
        rgb = WORLD_PALETTE[band]
        gy, gx = np.gradient(height * 40.0)
        shade = np.clip(1.0 - 0.6 * (gx + gy), 0.5, 1.4)[..., None]  # light from the top left
        rgb = cv2.resize(rgb * shade, (w, h), interpolation=cv2.INTER_LINEAR)
        rgb += rng.normal(0.0, 8.0, (h, w, 1)).astype(np.float32)  # fine texture (grass, waves, leaves)
        out.append(np.clip(rgb, 0, 255).astype(np.uint8))
    return out


def night(paths: list[Path]) -> list[np.ndarray]:
    """The city at night: each frame darkened to about 8% with a blue cast, sensor noise and a few street lights."""
    out = []
    for i, path in enumerate(paths):
        rng = np.random.default_rng([i, 88])
        rgb = read_image(path).astype(np.float32) * np.array([0.06, 0.07, 0.10], np.float32)
        h, w = rgb.shape[:2]
        for x, y in zip(rng.integers(0, w, 40), rng.integers(0, h, 40), strict=True):
            radius = max(1, int(rng.integers(6, 30)) * w // 3840)  # 6-30 px on a 4K frame
            cv2.circle(rgb, (int(x), int(y)), radius, (255, 220, 150), -1)
        rgb += rng.normal(0.0, 6.0, rgb.shape).astype(np.float32)
        out.append(np.clip(rgb, 0, 255).astype(np.uint8))
    return out


NIGHT_SCENES = 20


def frame_sets(root: Path, *, train_n: int | None = None, val_n: int | None = None, size: tuple[int, int] = SIZE,
               skip: frozenset[str] = frozenset()) -> Iterator[tuple[str, int, str, np.ndarray]]:
    """(set, scene, what, frame) for every frame of the study, in a fixed order; the generated sets at ``size``;
    the sets named in ``skip`` are not made."""
    if "train" not in skip:
        for i, what, rgb in training_frames(scene_images(root / "train", 0, train_n)):
            yield "train", i, what, rgb
    val = list(enumerate(scene_images(root / "val", 0, val_n)))
    if "val_sev3" not in skip:
        for i, what, rgb in validation_frames(val, (3,)):
            yield "val_sev3", i, what, rgb
    if "val_sev45" not in skip:
        for i, what, rgb in validation_frames(val[-SEV45_SCENES:], (4, 5), seed=4):
            yield "val_sev45", i, what, rgb
    for folder in sorted(root.glob("ood_*")):
        if folder.name not in skip:
            for i, path in enumerate(scene_images(folder)):
                yield folder.name, i, folder.name, read_image(path)
    generated = {"ood_noise": lambda: noise_frames(size=size), "ood_constant": lambda: constant_frames(size=size),
                 "ood_photos": lambda: photos(size), "ood_world": lambda: other_world(size=size),
                 "ood_night": lambda: night([p for _, p in val[:NIGHT_SCENES]])}
    for name, make in generated.items():
        if name not in skip:
            for i, rgb in enumerate(make()):
                yield name, i, name, rgb


KEYS = ("set", "scene", "what", "pooled", "energy", "msp")


def collect(root: Path, segmenter: Any, out: Path, **limits: Any) -> Path:
    """Tap every frame of :func:`frame_sets` with ``segmenter``'s frame pass; write ``out`` (npz). The cache is
    rewritten (atomically) as each set is finished, and a rerun taps only the sets it lacks."""
    import io

    import skimage.data  # noqa: F401  (the photographs' package: fail before tapping, not after an hour)

    old = load(out) if out.is_file() else {k: np.asarray([]) for k in KEYS}
    rows: dict[str, list[Any]] = {k: list(old[k]) for k in KEYS}
    done = frozenset(str(s) for s in rows["set"])

    def save() -> None:
        buf = io.BytesIO()
        np.savez_compressed(buf, **{k: np.asarray(v) for k, v in rows.items()})
        atomic_write_bytes(out, buf.getvalue())

    current = None
    for name, i, what, rgb in progress(frame_sets(root, skip=done, **limits), total=None, desc="frames"):
        if current is not None and name != current:
            save()
        current = name
        tap = segment_frame(segmenter, rgb, stats=True).stats
        for key, value in zip(KEYS, (name, i, what, tap.pooled, tap.energy, tap.msp), strict=True):
            rows[key].append(value)
    save()
    return out


def load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def main(argv: list[str] | None = None) -> int:
    root, out = (Path(a) for a in (argv or sys.argv[1:])[:2])
    collect(root, load_model(None), out)
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
