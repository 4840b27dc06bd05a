"""The frames of the frame-gate study (issue 32), each tapped once by the frame's own segmentation pass and kept
in one cache (``taps.npz``): the gate variants are then fitted and measured on the cached features in seconds.

Sets (the test split is never read): ``train`` (every training scene clean, under each in-domain perturbation at a
severity drawn from 1-3, seeded per scene, and under each at severity 3), ``val_sev3`` (every validation scene
clean and under each perturbation at severity 3), ``val_sev45`` (the last validation scenes under each
perturbation at severities 4 and 5), the ``ood_*`` folders of the data root (the synthetic city at poses outside the
declared domain, made with ``uav-el synth --heights/--pitches``), noise, constant frames and the scikit-image sample
photographs.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from assurance.campaign.perturbations import perturb
from assurance.scenes.uavid import iter_samples, read_image

IN_DOMAIN = ("none", "brightness", "fog", "motion_blur", "shifted_pixels", "pixel_trap")
SIZE = (1024, 576)
PHOTOS = ("astronaut", "chelsea", "coffee", "rocket", "hubble_deep_field", "retina", "brick", "grass", "gravel",
          "camera")  # scikit-image 0.26 package data: public domain or CC0 (each function's docstring says)
SEV45_SCENES = 20


def fit16x9(rgb: np.ndarray) -> np.ndarray:
    """Centre-crop to 16:9 and resize to ``SIZE``: the gate judges content, not the frame's shape."""
    h, w = rgb.shape[:2]
    if w / h > 16 / 9:
        c = round(h * 16 / 9)
        rgb = rgb[:, (w - c) // 2:(w - c) // 2 + c]
    else:
        c = round(w * 9 / 16)
        rgb = rgb[(h - c) // 2:(h - c) // 2 + c]
    return cv2.resize(np.ascontiguousarray(rgb), SIZE, interpolation=cv2.INTER_AREA)


def scene_images(data: Path, first: int = 0, count: int | None = None) -> list[Path]:
    samples = list(iter_samples(data, require_labels=False))[first:None if count is None else first + count]
    return [s.image_path for s in samples]


def perturbed(rgb: np.ndarray, name: str, severity: int, seed: Any) -> np.ndarray:
    return rgb if name == "none" else perturb(rgb, name, severity, np.random.default_rng(seed))


def training_frames(paths: list[Path], seed: int = 1) -> Iterator[tuple[int, str, np.ndarray]]:
    """Every training scene clean, under each in-domain perturbation at a severity in 1-3 (seeded per scene), and
    under each at severity 3, the declared maximum (11 frames a scene)."""
    for i, path in enumerate(paths):
        rgb = read_image(path)
        sev = np.random.default_rng([seed, i]).integers(1, 4, len(IN_DOMAIN))
        for name, s in zip(IN_DOMAIN, sev, strict=True):
            yield i, f"{name}:{0 if name == 'none' else int(s)}", perturbed(rgb, name, int(s), [seed, i, int(s)])
        for name in IN_DOMAIN[1:]:
            yield i, f"{name}:3", perturbed(rgb, name, 3, [seed + 4, i, 3])


def validation_frames(paths: list[tuple[int, Path]], severities: tuple[int, ...], seed: int = 3
                      ) -> Iterator[tuple[int, str, np.ndarray]]:
    """Every (index, validation scene) under each perturbation at each of ``severities`` (clean once, when 3 is
    asked)."""
    for i, path in paths:
        rgb = read_image(path)
        for name in IN_DOMAIN:
            for s in severities:
                if name == "none" and s != 3:
                    continue
                yield i, f"{name}:{0 if name == 'none' else s}", perturbed(rgb, name, s, [seed, i, s])


def synthetic_ood(seed: int = 0, n: int = 10) -> dict[str, list[np.ndarray]]:
    """Uniform noise, Gaussian noise around grey, and constant frames (black, white, grey, colours)."""
    rng = np.random.default_rng(seed)
    w, h = SIZE
    noise = [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(n // 2)]
    noise += [np.clip(rng.normal(128, 40, (h, w, 3)), 0, 255).astype(np.uint8) for _ in range(n - n // 2)]
    levels = np.linspace(0, 255, n)
    const = [np.full((h, w, 3), (int(v), int(255 - v), int(v // 2)) if i % 2 else int(v), np.uint8)
             for i, v in enumerate(levels)]
    return {"ood_noise": noise, "ood_constant": const}


def photos() -> list[np.ndarray]:
    import skimage.data

    out = []
    for name in PHOTOS:
        img = getattr(skimage.data, name)()
        img = np.repeat(img[..., None], 3, axis=2) if img.ndim == 2 else img[..., :3]
        out.append(fit16x9(img.astype(np.uint8)))
    return out


def frame_sets(root: Path, *, train_n: int | None = None, val_n: int | None = None
               ) -> Iterator[tuple[str, int, str, np.ndarray]]:
    """(set, scene, what, frame) for every frame of the study, in a fixed order."""
    for i, what, rgb in training_frames(scene_images(root / "train", 0, train_n)):
        yield "train", i, what, rgb
    val = list(enumerate(scene_images(root / "val", 0, val_n)))
    for i, what, rgb in validation_frames(val, (3,)):
        yield "val_sev3", i, what, rgb
    for i, what, rgb in validation_frames(val[-SEV45_SCENES:], (4, 5), seed=4):
        yield "val_sev45", i, what, rgb
    for folder in sorted(root.glob("ood_*")):
        for i, path in enumerate(scene_images(folder)):
            yield folder.name, i, folder.name, read_image(path)
    for name, frames in {**synthetic_ood(), "ood_photos": photos()}.items():
        for i, rgb in enumerate(frames):
            yield name, i, name, rgb


def collect(root: Path, segmenter: Any, out: Path, **limits: Any) -> Path:
    """Tap every frame of :func:`frame_sets` with ``segmenter``'s frame pass; write ``out`` (npz)."""
    from assurance.progress import progress

    segmenter.tap_frames = True
    rows: dict[str, list[Any]] = {"set": [], "scene": [], "what": [], "pooled": [], "energy": [], "msp": []}
    for name, i, what, rgb in progress(frame_sets(root, **limits), total=None, desc="frames"):
        segmenter.predict_frame(rgb)
        tap = segmenter.last_tap
        for key, value in (("set", name), ("scene", i), ("what", what), ("pooled", tap.pooled),
                           ("energy", tap.energy), ("msp", tap.msp)):
            rows[key].append(value)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, **{k: np.asarray(v) for k, v in rows.items()})
    return out


def load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def main(argv: list[str] | None = None) -> int:
    from el.segmentation.factory import load_model

    root, out = (Path(a) for a in (argv or sys.argv[1:])[:2])
    collect(root, load_model(None, working_width=SIZE[0]), out)
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
