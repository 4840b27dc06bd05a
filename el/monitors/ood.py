"""Out-of-domain frame gate: how far a frame's encoder features lie from the training distribution.

A frame far from what the network was trained on (a lens covered, a sensor fault, thick fog, a place
unlike the training cities) makes every softmax, and so every candidate monitor, unreliable; the
safe answer is the default action, with reason ``out_of_domain`` (``el.pipeline``).

Embedding (:func:`frame_embedding`) of the working-resolution frame:

- ``trunk``: the segmentation network's deterministic trunk (``model.trunk(x)``), deepest level
  (``Features.deep`` of MSDLite, ``LiteFeatures.levels[0]`` (1/32) of LiteSeg), pooled over space: the
  mean and the standard deviation of each channel;
- ``softmax``: for segmenters without a trunk, the frame softmax's mean class probabilities, the
  share of pixels of each top class, and the mean and standard deviation of the normalised entropy.

Score: the Mahalanobis distance ``sqrt((x - mu)^T P (x - mu))`` to the training frames' mean ``mu``,
``P`` the shrunk (Ledoit-Wolf) precision, both fitted on the train split (``uav-el fit-ood``); the
threshold is a stated quantile of the validation frames' distances. The gate file is plain JSON with
the SHA-256 of its body (like calibration cards): an altered or missing file is refused at load.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np

from el.errors import OODError
from el.records import HashedRecord
from el.segmentation.contract import TRUNK_FEATURES, has_capability

OOD_FORMAT = "uav-el-ood/1"
TRUNK, SOFTMAX = "trunk", "softmax"


def deepest_level(features: Any) -> Any:
    """The deepest feature map (B, C, h, w) of a trunk's output: MSDLite's ``deep``, LiteSeg's ``levels[0]``,
    or a tensor itself."""
    if hasattr(features, "deep"):
        return features.deep
    if hasattr(features, "levels"):
        return features.levels[0]
    if hasattr(features, "ndim") and features.ndim == 4:
        return features
    raise ValueError(f"cannot pool the trunk's output ({type(features).__name__})")


def embedding_kind(segmenter: Any) -> str:
    """``trunk`` when the segmenter's network exposes ``trunk``, else ``softmax``."""
    return TRUNK if has_capability(segmenter, TRUNK_FEATURES) else SOFTMAX


def softmax_embedding(probs: np.ndarray) -> np.ndarray:
    """Mean class probability (8), top-class shares (8), mean and std of the normalised entropy (2)."""
    probs = np.asarray(probs, np.float64)
    if probs.ndim != 3 or probs.shape[0] < 2:
        raise ValueError(f"frame probabilities must be (C, h, w) with C >= 2 classes, got {probs.shape}")
    c = probs.shape[0]  # the label set's size, as the network gives it
    p = np.clip(probs, 0.0, 1.0).reshape(c, -1)
    top = np.bincount(p.argmax(axis=0), minlength=c) / p.shape[1]
    ent = -(p * np.log(np.where(p > 0, p, 1.0))).sum(axis=0) / math.log(c)
    return np.concatenate([p.mean(axis=1), top, [ent.mean(), ent.std()]])


def trunk_embedding(segmenter: Any, rgb: np.ndarray) -> np.ndarray:
    """Per-channel mean and std over space of the deepest trunk level of the working-resolution frame."""
    import torch

    w, h = segmenter.working_size(rgb.shape[1], rgb.shape[0])
    frame = rgb if (rgb.shape[1], rgb.shape[0]) == (w, h) else cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
    model = segmenter.model
    device = getattr(segmenter, "device", "cpu")
    x = torch.from_numpy(np.ascontiguousarray(frame, np.float32) / np.float32(255.0)).permute(2, 0, 1)[None]
    with torch.inference_mode():
        deep = deepest_level(model.trunk(x.contiguous().to(device))).float()[0]
        flat = deep.reshape(deep.shape[0], -1)
        out = torch.cat([flat.mean(dim=1), flat.std(dim=1, correction=0)])
    return out.cpu().numpy().astype(np.float64)


def frame_embedding(segmenter: Any, rgb: np.ndarray, probs: np.ndarray | None = None, kind: str | None = None
                    ) -> np.ndarray:
    """The frame's embedding of ``kind`` (default: :func:`embedding_kind`); ``probs``: its softmax, if known."""
    kind = kind or embedding_kind(segmenter)
    if kind == TRUNK:
        if embedding_kind(segmenter) != TRUNK:
            raise ValueError("the out-of-domain gate needs the network's trunk; this segmenter has none")
        vec = trunk_embedding(segmenter, rgb)
    elif kind == SOFTMAX:
        vec = softmax_embedding(segmenter.predict_frame(rgb) if probs is None else probs)
    else:
        raise ValueError(f"unknown embedding kind {kind!r}")
    if not np.isfinite(vec).all():
        raise ValueError("non-finite frame embedding")
    return vec


@dataclass(frozen=True)
class OODGate(HashedRecord):
    """A checked gate (:func:`load_ood`): mean, precision, threshold and the embedding kind."""

    FORMAT: ClassVar[str] = OOD_FORMAT
    WHAT: ClassVar[str] = "out-of-domain gate"
    ARTICLE: ClassVar[str] = "an"
    ERROR: ClassVar[type[ValueError]] = OODError

    mean: np.ndarray
    precision: np.ndarray

    @property
    def kind(self) -> str:
        return str(self.body["embedding"])

    @property
    def threshold(self) -> float:
        return float(self.body["threshold"])

    def distance(self, x: np.ndarray) -> float:
        """Mahalanobis distance of one embedding (d,) to the training mean."""
        x = np.asarray(x, np.float64)
        if x.shape != self.mean.shape:
            raise ValueError(f"frame embedding has {x.shape[0] if x.ndim == 1 else x.shape} values, the gate "
                             f"{self.path} expects {self.mean.shape[0]} (another network?)")
        v = x - self.mean
        return float(math.sqrt(max(float(v @ self.precision @ v), 0.0)))

    def score(self, segmenter: Any, rgb: np.ndarray, probs: np.ndarray | None = None) -> float:
        """The frame's distance (higher = further from the training frames)."""
        return self.distance(frame_embedding(segmenter, rgb, probs, self.kind))


def ood_document(body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a gate with this body (format and hash added)."""
    return OODGate.document(body)


def load_ood(path: str | Path) -> OODGate:
    """Read and check a gate file: format, body hash, shapes, finite numbers.

    Raises
    ------
    OODError
        One line naming the file and the problem.
    """
    p = Path(path)
    body, digest = OODGate.read_body(p)
    try:
        mean = np.asarray(body["mean"], np.float64)
        precision = np.asarray(body["precision"], np.float64)
        d = mean.shape[0] if mean.ndim == 1 else -1
        if d < 1 or precision.shape != (d, d) or not (np.isfinite(mean).all() and np.isfinite(precision).all()):
            raise ValueError("mean (d,) and precision (d, d) of finite numbers expected")
        if body["embedding"] not in (TRUNK, SOFTMAX) or not math.isfinite(float(body["threshold"])):
            raise ValueError("embedding must be trunk or softmax, threshold finite")
    except (KeyError, TypeError, ValueError) as exc:
        raise OODError(f"{p}: inconsistent out-of-domain gate ({exc})") from None
    return OODGate(str(p), digest, body, mean, precision)
