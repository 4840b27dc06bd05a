"""The shipped network without torch: its ONNX export under ONNX Runtime, as the :class:`Segmenter` of a base install.

torch is an optional heavy dependency (the ``train`` extra). When it is not installed, the shipped network (or any
``.pt`` weights file with an export record beside it, ``uav-el export-onnx --beside``) runs here: the same card
(identity ``weights_sha256``, labels, evaluation protocol), the weights file's SHA-256 checked against the card as
:func:`el.segmentation.weights.load_weights` does, the export checked against its record
(:mod:`el.segmentation.onnx_engine`), the same frame steps (:class:`~el.segmentation.frame_passes.FramePasses`), the
same patch passes (:class:`~el.segmentation.patch_passes.PatchPasses`) and the same frame statistics for a frame
gate. A full install runs the same ONNX Runtime passes (``UAV_EL_ENGINE=auto``) and takes their softmax with torch;
here numpy takes it: the scores agree to float rounding (about 1e-7) and the decisions are the same (checked by
``tests/test_light_install.py`` and ``.ci/wheel-check``). It offers no MC dropout and no trunk for monitors (torch
runs them): a monitor that needs them is refused before any frame, naming the ``train`` extra.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from el.base.errors import WeightsError
from el.base.torch_extra import TorchMissing, missing_line
from el.classes.labels import UAVID, LabelSet
from el.segmentation.batching import unit_nchw
from el.segmentation.frame_passes import FramePasses, check_finite, check_frame_rgb
from el.segmentation.frame_tap import FrameTap, frame_tap
from el.segmentation.onnx_engine import ENGINE_ENV, _checked_engine, engine_choice, onnxruntime, record_path
from el.segmentation.patch_passes import PatchPasses
from el.segmentation.pooling import check_pooling
from el.segmentation.protocol import card_protocol, check_frame_scales
from el.segmentation.weights import DEFAULT_WEIGHTS, card_path, checked_weights

INPUT_MULTIPLE = {"lite0": 32, "msdlite": 8}
"""What each shipped architecture edge-pads its input to (its ``stride``; ``el.segmentation.batching``): patches of
one padded size share a pass padded as the torch network pads them (a test checks the table against the networks)."""


def softmax_np(logits: np.ndarray) -> np.ndarray:
    """Softmax over the class axis of (B, C, H, W) float32 logits, in numpy (torch's ``softmax(dim=1)``)."""
    z = np.asarray(logits, dtype=np.float32)
    z = z - z.max(axis=1, keepdims=True)
    np.exp(z, out=z)
    z /= z.sum(axis=1, keepdims=True)
    return z


class OnnxSegmenter(FramePasses, PatchPasses):
    """The shipped network (or a ``.pt`` network with its checked ONNX export) under ONNX Runtime, without torch.

    Build it with :meth:`load`; the attributes are :class:`~el.segmentation.inference.Segmenter`'s (``card``,
    ``labels``, ``working_width``, ``frame_flip``, ``frame_scales``, ``frame_pooling``, ``engine``; frames with their
    statistics, ``predict_frame(rgb, stats=True)``), ``model`` is None (no torch module)."""

    labels: LabelSet
    model = None
    fast_mc = False
    has_dropout = False
    engine_name = "onnx"

    def __init__(self, engine: Any, *, card: dict[str, Any], labels: LabelSet, working_width: int = 1024,
                 frame_flip: bool = False, frame_scales: Sequence[float] = (1.0,), frame_pooling: str = "area",
                 input_multiple: int = 1) -> None:
        if working_width < 16:
            raise ValueError(f"working_width must be >= 16, got {working_width!r}")
        self.engine, self.card, self.labels = engine, dict(card), labels
        self.working_width = int(working_width)
        self.frame_flip = bool(frame_flip)
        self.frame_scales = check_frame_scales(frame_scales)
        self.frame_pooling = check_pooling(frame_pooling)
        self.input_multiple = int(input_multiple)
        self._lock = threading.Lock()

    @classmethod
    def load(cls, weights_path: str | Path | None = None, *, threads: int | None = None,
             working_width: int = 1024) -> OnnxSegmenter:
        """The shipped network (``el/segmentation/weights/model.pt``'s card and its export ``model.onnx``) or another
        weights file's; ``WeightsError`` (``TorchMissing`` when only torch could run it) naming the problem."""
        path, _, card = checked_weights(weights_path)
        if engine_choice() == "torch":
            raise TorchMissing(missing_line(f"{ENGINE_ENV}=torch"))
        if not record_path(path).is_file():
            raise TorchMissing(f"{missing_line(str(path))}; without torch it runs from its checked ONNX export, and "
                               f"{record_path(path).name} is not beside it (uav-el export-onnx --beside)")
        onnxruntime()  # a one-line WeightsError naming the package when ONNX Runtime is missing
        engine = _checked_engine(path, card.get("weights_sha256"), threads)  # an altered export: WeightsError
        labels = UAVID
        if card.get("labels") is not None:
            try:
                labels = LabelSet.from_dict(card["labels"])
            except ValueError as err:
                raise WeightsError(f"{card_path(path if weights_path is not None else DEFAULT_WEIGHTS)}: model card "
                                   f"'labels': {err}") from None
        arch = card.get("architecture") or {}
        multiple = INPUT_MULTIPLE.get(str(arch.get("name", "msdlite")), 1) if isinstance(arch, dict) else 1
        return cls(engine, card=card, labels=labels, working_width=working_width, input_multiple=multiple,
                   **card_protocol(card).frame_options())

    def __getstate__(self) -> dict[str, Any]:  # picklable (worker processes): the lock and the pool are recreated
        state = self.__dict__.copy()
        del state["_lock"]
        state.pop("_pool", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    @property
    def weights_sha256(self) -> str | None:
        return self.card.get("weights_sha256")

    def _padding_multiple(self) -> int:
        return self.input_multiple

    def _engine_probs(self, logits: np.ndarray, shape: tuple[int, ...], what: str) -> np.ndarray:
        if not isinstance(logits, np.ndarray) or tuple(logits.shape) != shape:
            got = tuple(logits.shape) if isinstance(logits, np.ndarray) else type(logits).__name__
            raise ValueError(f"{what}: model returned {got}, expected logits of shape {shape}")
        return check_finite(softmax_np(logits), what)

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        """Softmax of a patch at its own resolution: ndarray (C, h, w) float32 for a (h, w, 3) uint8 patch."""
        check_frame_rgb(rgb_patch, "patch")
        return self._predict([rgb_patch], "patch")[0]

    def _predict(self, images: list[np.ndarray], what: str) -> np.ndarray:
        return self._run(images, what, False)[0]

    def _frame_pass(self, images: list[np.ndarray], stats: bool) -> tuple[np.ndarray, FrameTap | None]:
        return self._run(images, "frame", stats)

    def _run(self, images: list[np.ndarray], what: str, stats: bool) -> tuple[np.ndarray, FrameTap | None]:
        """The softmax of a batch and, with ``stats``, the statistics of its first image from this very pass."""
        h, w = images[0].shape[:2]
        batch = unit_nchw(images)
        features = None
        if stats and getattr(self.engine, "trunk_names", None):  # one pass, the trunk's outputs kept
            logits, features = self.engine.with_trunk(batch)
        else:
            logits = self.engine.logits(batch)
        probs = self._engine_probs(logits, (len(images), self.labels.num_classes, h, w), what)
        return np.ascontiguousarray(probs), (frame_tap(logits, features) if stats else None)
