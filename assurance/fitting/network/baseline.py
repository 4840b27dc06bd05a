"""Per-pixel baseline for the model card: logistic regression on colour and local texture.

Features per working-resolution pixel (15): RGB, and the local mean and variance of RGB in 5x5 and
15x15 boxes. docs/architecture.md section 5.2 asks that such a colour classifier does far worse than the CNN (the
issue: at least 0.2 mIoU below), otherwise the scenes are too easy for the campaign to prove anything.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from assurance.fitting.network.evaluation import confusion, summarise
from el.base.rgb import check_rgb
from el.classes.labels import NUM_CLASSES

BOX_SIZES = (5, 15)
FEATURE_NAMES: tuple[str, ...] = (
    "r", "g", "b",
    *(f"{stat}{k}_{c}" for k in BOX_SIZES for stat in ("mean", "var") for c in "rgb"),
)


def pixel_features(rgb: np.ndarray) -> np.ndarray:
    """Features of every pixel of an RGB uint8 image (H, W, 3): float32 (H * W, 15)."""
    check_rgb(rgb, "image")
    img = rgb.astype(np.float32) / 255.0
    parts = [img]
    for k in BOX_SIZES:
        mean = cv2.blur(img, (k, k), borderType=cv2.BORDER_REFLECT)
        sq = cv2.blur(img * img, (k, k), borderType=cv2.BORDER_REFLECT)
        parts += [mean, np.maximum(sq - mean * mean, 0.0)]
    return np.concatenate(parts, axis=2).reshape(-1, len(FEATURE_NAMES))


class PixelBaseline:
    """Multinomial logistic regression on :func:`pixel_features`, class-balanced.

    Parameters
    ----------
    max_pixels : int
        Training pixels sampled (uniformly, seeded) over all training images.
    seed : int
        Seed of the pixel sample.
    max_iter : int
        L-BFGS iterations; ``converged_`` says whether the solver converged within them (the fit is
        deterministic either way).
    """

    def __init__(self, *, max_pixels: int = 200_000, seed: int = 0, max_iter: int = 300) -> None:
        if max_pixels < NUM_CLASSES:
            raise ValueError(f"max_pixels must be >= {NUM_CLASSES}, got {max_pixels!r}")
        if max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {max_iter!r}")
        self.max_pixels = int(max_pixels)
        self.seed = int(seed)
        self.max_iter = int(max_iter)

    def fit(self, images: Sequence[np.ndarray], labels: Sequence[np.ndarray]) -> PixelBaseline:
        if len(images) != len(labels) or not images:
            raise ValueError("need the same, non-zero number of images and label maps")
        rng = np.random.default_rng(self.seed)
        per_image = max(1, self.max_pixels // len(images))
        xs, ys = [], []
        for img, lab in zip(images, labels, strict=True):
            feats = pixel_features(img)
            idx = rng.choice(feats.shape[0], size=min(per_image, feats.shape[0]), replace=False)
            xs.append(feats[idx])
            ys.append(lab.ravel()[idx])
        x, y = np.concatenate(xs), np.concatenate(ys)
        if len(np.unique(y)) < 2:
            raise ValueError("the baseline needs at least two classes in the training pixels")
        self.model_ = make_pipeline(StandardScaler(),
                                    LogisticRegression(max_iter=self.max_iter, class_weight="balanced"))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            self.model_.fit(x, y)
        self.converged_ = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
        return self

    def predict(self, rgb: np.ndarray) -> np.ndarray:
        """Class ids (H, W) uint8 of an RGB image."""
        h, w = rgb.shape[:2]
        return self.model_.predict(pixel_features(rgb)).reshape(h, w).astype(np.uint8)


def evaluate_baseline(train_images: Sequence[np.ndarray], train_labels: Sequence[np.ndarray],
                      val_images: Sequence[np.ndarray], val_labels: Sequence[np.ndarray], *,
                      max_pixels: int = 200_000, seed: int = 0, max_iter: int = 300) -> dict[str, Any]:
    """Fit on the training frames, score the validation frames (working resolution) as :func:`summarise`."""
    model = PixelBaseline(max_pixels=max_pixels, seed=seed, max_iter=max_iter).fit(train_images, train_labels)
    conf = np.zeros((NUM_CLASSES, NUM_CLASSES), np.int64)
    for img, lab in zip(val_images, val_labels, strict=True):
        conf += confusion(lab, model.predict(img))
    result = summarise(conf)
    result.update({"name": "logistic regression on RGB + 5x5/15x15 local mean and variance",
                   "features": list(FEATURE_NAMES), "max_pixels": max_pixels, "seed": seed,
                   "max_iter": model.max_iter, "converged": model.converged_})
    return result
