"""A network from elsewhere: an ``.onnx`` file under ONNX Runtime, behind the segmentation seam.

:class:`OnnxContract` says how the file wants its input and what its output is (docs/architecture.md
section 3.2):

- **size rule** ``size``: ``any`` (any H, W >= 16), ``multiple`` (H and W multiples of ``multiple``: the
  input is edge-padded up to one and the output cropped back) or ``fixed`` (``fixed_size`` (W, H): the input
  is resized to it, bilinear, and the output resized back). Frames are first brought to the working
  resolution (``cv2.INTER_AREA``, as the shipped :class:`~el.segmentation.inference.Segmenter`); HD patches
  go in at their own resolution, under the same rule.
- ``channel_order`` ``rgb`` | ``bgr``; ``scaling`` ``unit`` (values in [0, 1]) or ``mean_std``
  (``(v - mean) / std`` per channel, on values in [0, ``value_range``], 255 or 1; a mapping giving ``mean``
  and ``std`` without ``scaling`` means ``mean_std``);
  ``layout`` ``nchw`` | ``nhwc`` for the input, ``output_layout`` for the output (default: the input's);
  float32 input, one input, batch of one.
- ``output`` ``logits`` (softmax applied here) | ``probabilities``; its channels are ``class_names``, in
  order. Given the system's label set, the names must be exactly its classes, in any order (outputs are
  permuted onto the label set's ids); given none, they are the network's own classes
  (:class:`~el.segmentation.contract.OutputClasses`), for a class map onto the system's. The output must
  have the input's spatial size.

A file exported by ``uav-el export-onnx`` carries its contract, its label set, its opset and the source
weights' SHA-256 in the ONNX ``metadata_props`` (:data:`META_CONTRACT`, ...), so it loads with no further
configuration; a file exported elsewhere needs none of them when its contract is given. The model's identity
(``weights_sha256``, what a system file pins, what cards and fitted monitors bind to, what the manifest
records) is the SHA-256 of the ``.onnx`` file, or, for a file with external data, the SHA-256 of a listing of
it and its external files (:func:`el.segmentation.onnx_engine.read_onnx`). Frames are brought to the model's
``working_width``. It offers no MC dropout and no trunk: monitors that need them are refused before any
decision (``el.monitors.capabilities``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np

from el.base.deadline import checkpoint
from el.base.errors import WeightsError
from el.base.rgb import check_rgb
from el.classes.labels import LabelSet
from el.geometry.camera import working_size
from el.segmentation.contract import OutputClasses
from el.segmentation.frame_tap import FramePass, FrameTap, frame_tap
from el.segmentation.onnx_engine import metadata, open_session, read_checked, run_session, shipped_export_source

MIN_SIZE = 16
META_CONTRACT = "uav_el.contract"
META_LABELS = "uav_el.labels"
META_OPSET = "uav_el.opset"
META_SOURCE = "uav_el.source_weights_sha256"


def _choice(name: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ValueError(f"ONNX contract {name}: {value!r} is not one of {', '.join(allowed)}")


def _triple(name: str, value: Any) -> tuple[float, float, float]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"ONNX contract {name}: expected 3 numbers, got {value!r}") from None
    if len(out) != 3 or not all(math.isfinite(v) for v in out):
        raise ValueError(f"ONNX contract {name}: expected 3 finite numbers, got {value!r}")
    return out  # type: ignore[return-value]


@dataclass(frozen=True)
class OnnxContract:
    """How an ONNX network wants its input and what its output channels are (see the module docstring)."""

    SIZES: ClassVar[tuple[str, ...]] = ("any", "multiple", "fixed")
    class_names: tuple[str, ...]
    size: str = "any"
    multiple: int | None = None
    fixed_size: tuple[int, int] | None = None  # (W, H)
    channel_order: str = "rgb"
    scaling: str = "unit"
    mean: tuple[float, float, float] | None = None
    std: tuple[float, float, float] | None = None
    value_range: float = 1.0
    layout: str = "nchw"
    output_layout: str | None = None
    output: str = "logits"

    def __post_init__(self) -> None:
        names = tuple(self.class_names) if isinstance(self.class_names, (list, tuple)) else None
        if not names or not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
            raise ValueError(f"ONNX contract class_names: a list of distinct names expected, got {self.class_names!r}")
        object.__setattr__(self, "class_names", names)
        _choice("size", self.size, self.SIZES)
        if self.size == "multiple":
            if isinstance(self.multiple, bool) or not isinstance(self.multiple, int) or self.multiple < 1:
                raise ValueError(f"ONNX contract multiple: a positive integer expected, got {self.multiple!r}")
        elif self.multiple is not None:
            raise ValueError(f"ONNX contract multiple: only with size 'multiple' (size is {self.size!r})")
        if self.size == "fixed":
            fs = self.fixed_size
            if (not isinstance(fs, (list, tuple)) or len(fs) != 2
                    or not all(isinstance(v, int) and not isinstance(v, bool) and v >= MIN_SIZE for v in fs)):
                raise ValueError(f"ONNX contract fixed_size: [W, H], integers >= {MIN_SIZE}, expected, got {fs!r}")
            object.__setattr__(self, "fixed_size", (int(fs[0]), int(fs[1])))
        elif self.fixed_size is not None:
            raise ValueError(f"ONNX contract fixed_size: only with size 'fixed' (size is {self.size!r})")
        _choice("channel_order", self.channel_order, ("rgb", "bgr"))
        _choice("scaling", self.scaling, ("unit", "mean_std"))
        if self.scaling == "mean_std":
            object.__setattr__(self, "mean", _triple("mean", self.mean))
            std = _triple("std", self.std)
            if min(std) <= 0:
                raise ValueError(f"ONNX contract std: must be positive, got {self.std!r}")
            object.__setattr__(self, "std", std)
        elif self.mean is not None or self.std is not None:
            raise ValueError("ONNX contract mean/std: only with scaling 'mean_std'")
        if self.value_range not in (1, 1.0, 255, 255.0) or isinstance(self.value_range, bool):
            raise ValueError(f"ONNX contract value_range: 1 or 255 expected, got {self.value_range!r}")
        object.__setattr__(self, "value_range", float(self.value_range))
        _choice("layout", self.layout, ("nchw", "nhwc"))
        if self.output_layout is None:
            object.__setattr__(self, "output_layout", self.layout)
        _choice("output_layout", self.output_layout, ("nchw", "nhwc"))
        _choice("output", self.output, ("logits", "probabilities"))

    @classmethod
    def from_dict(cls, data: Any) -> OnnxContract:
        """A contract from a JSON/TOML mapping; a ValueError naming an unknown or malformed key."""
        if not isinstance(data, dict):
            raise ValueError(f"ONNX contract: a mapping expected, got {type(data).__name__}")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"ONNX contract: unknown keys {unknown} (known: {sorted(known)})")
        if "class_names" not in data:
            raise ValueError("ONNX contract: class_names is missing (the output channels' class names, in order)")
        if "scaling" not in data and ("mean" in data or "std" in data):  # mean and std say how to scale
            data = {**data, "scaling": "mean_std"}
        return cls(**data)

    def to_dict(self) -> dict[str, Any]:
        """The contract as plain JSON values (what the ONNX metadata and a system file hold)."""
        out = asdict(self)
        out["class_names"] = list(self.class_names)
        for key in ("fixed_size", "mean", "std"):
            if out[key] is not None:
                out[key] = list(out[key])
        return out

    # -- input and output ----------------------------------------------------------------------
    def net_size(self, width: int, height: int) -> tuple[int, int]:
        """(W, H) the network is fed for an image of this size."""
        if self.size == "fixed":
            return self.fixed_size  # type: ignore[return-value]
        if self.size == "multiple":
            m = int(self.multiple)  # type: ignore[arg-type]
            return -(-width // m) * m, -(-height // m) * m
        return width, height

    def to_input(self, rgb: np.ndarray) -> np.ndarray:
        """The network's input (1, 3, H', W') or (1, H', W', 3), float32, of an RGB uint8 image."""
        h, w = rgb.shape[:2]
        nw, nh = self.net_size(w, h)
        img = rgb
        if self.size == "fixed" and (nw, nh) != (w, h):
            img = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_LINEAR)
        elif (nw, nh) != (w, h):
            img = np.pad(rgb, ((0, nh - h), (0, nw - w), (0, 0)), mode="edge")
        if self.channel_order == "bgr":
            img = img[:, :, ::-1]
        x = img.astype(np.float32) * np.float32(self.value_range / 255.0)
        if self.scaling == "mean_std":
            x = (x - np.asarray(self.mean, np.float32)) / np.asarray(self.std, np.float32)
        x = x[None]
        return np.ascontiguousarray(x if self.layout == "nhwc" else x.transpose(0, 3, 1, 2), dtype=np.float32)

    def to_probs(self, out: Any, width: int, height: int, what: str) -> np.ndarray:
        """(C, height, width) float32 probabilities, channels in the contract's order, from the raw output."""
        nw, nh = self.net_size(width, height)
        c = len(self.class_names)
        a = np.asarray(out)
        if self.output_layout == "nhwc" and a.ndim == 4:
            a = a.transpose(0, 3, 1, 2)
        if a.ndim != 4 or a.shape != (1, c, nh, nw):
            raise ValueError(f"{what}: the ONNX output is {np.asarray(out).shape} ({self.output_layout}), expected "
                             f"{c} class channels at the input's {nh}x{nw} (batch 1)")
        a = a[0].astype(np.float32, copy=False)
        if not np.isfinite(a).all():
            raise ValueError(f"{what}: the ONNX output has {int((~np.isfinite(a)).sum())} non-finite values")
        if self.output == "logits":
            a = np.exp(a - a.max(axis=0, keepdims=True))
        elif (a < 0).any():
            raise ValueError(f"{what}: the ONNX output declared 'probabilities' has negative values")
        total = a.sum(axis=0, keepdims=True)
        if not (total > 0).all():
            raise ValueError(f"{what}: the ONNX output has pixels whose probabilities sum to 0")
        a = a / total
        if self.size == "fixed" and (nw, nh) != (width, height):
            hwc = cv2.resize(np.ascontiguousarray(a.transpose(1, 2, 0)), (width, height),
                             interpolation=cv2.INTER_LINEAR)
            a = hwc.reshape(height, width, c).transpose(2, 0, 1)
        elif (nw, nh) != (width, height):
            a = a[:, :height, :width]
        return a


def contract_from_metadata(meta: dict[str, str], where: str | Path) -> OnnxContract:
    """The contract an exported file carries (``metadata_props``); a WeightsError naming what is missing."""
    if META_CONTRACT not in meta:
        raise WeightsError(f"{where}: no input contract given and the file's metadata has no {META_CONTRACT!r} "
                           "(give contract=OnnxContract(...): size rule, channel order, scaling, layout, output, "
                           "class_names)")
    try:
        return OnnxContract.from_dict(json.loads(meta[META_CONTRACT]))
    except (ValueError, TypeError) as exc:
        raise WeightsError(f"{where}: metadata {META_CONTRACT!r}: {exc}") from None


class OnnxModel:
    """A :class:`el.segmentation.contract.SegmentationModel` running an ONNX file (:func:`load_onnx_model`).

    ``labels``: the system's label set, or the network's own :class:`OutputClasses`; ``weights_sha256``: the
    file's identity; ``contract``; ``path``. Picklable (worker processes): the session is opened again from
    the file, checked against its identity. ``predict_frame(rgb, stats=True)``: the frame's probabilities with the
    statistics of the same pass for a frame gate (``el.segmentation.frame_tap``): the output's always, the trunk's
    when the file declares trunk outputs (``trunk.*``, as ``uav-el export-onnx`` writes them)."""

    frame_stats = True  # el.segmentation.contract.FRAME_STATS

    def __init__(self, path: str | Path, contract: OnnxContract, labels: LabelSet | OutputClasses, sha256: str, *,
                 threads: int | None = None, working_width: int = 1024, session: Any = None) -> None:
        self.path, self.contract, self.labels = str(path), contract, labels
        self.weights_sha256, self.threads, self.working_width = sha256, threads, int(working_width)
        self.source_weights_sha256 = shipped_export_source(sha256)  # the shipped weights, for their packaged export
        if session is None:
            session = open_session(read_checked(path, sha256)[0], path, threads)
        self._session = session
        inputs = self._session.get_inputs()
        if len(inputs) != 1:
            raise WeightsError(f"{path}: the ONNX model has {len(inputs)} inputs, one (the image) expected")
        self._input = inputs[0].name
        self._batch_free = not isinstance(inputs[0].shape[0], int)  # a free batch axis: patches may share a pass
        outputs = [o.name for o in self._session.get_outputs()]
        self._output = outputs[0]  # the first output; an export's trunk outputs only for a frame gate's tap
        self._trunk = [n for n in outputs[1:] if n.startswith("trunk.")]
        missing = sorted(set(labels.names) ^ set(contract.class_names))
        if len(contract.class_names) != labels.num_classes or missing:
            raise WeightsError(f"{path}: the contract's classes {list(contract.class_names)} are not the label "
                               f"set {labels.name!r}'s {list(labels.names)} (differ: {missing}); name the "
                               "network's classes and map them with a class map")
        # output channel of each label id: outputs are permuted onto the label set's order
        self._order = np.array([contract.class_names.index(n) for n in labels.names])

    def __getstate__(self) -> dict[str, Any]:
        skip = ("_session", "_input", "_output", "_order", "_batch_free", "_trunk")
        return {k: v for k, v in self.__dict__.items() if k not in skip}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"], state["contract"], state["labels"], state["weights_sha256"],  # type: ignore[misc]
                      threads=state["threads"], working_width=state["working_width"])

    def working_size(self, width: int, height: int) -> tuple[int, int]:
        """(width, height) of the working resolution for a frame of the given size."""
        return working_size(width, height, self.working_width)

    def _run(self, rgb: np.ndarray, what: str, stats: bool = False) -> tuple[np.ndarray, FrameTap | None]:
        """The probabilities of one image and, with ``stats``, the statistics of this very pass."""
        h, w = rgb.shape[:2]
        names = [self._output, *(self._trunk if stats else [])]
        outs = run_session(self._session, names, {self._input: self.contract.to_input(rgb)}, f"{what} segmentation")
        out = outs[0]
        probs = np.ascontiguousarray(self.contract.to_probs(out, w, h, what)[self._order], dtype=np.float32)
        if not stats:
            return probs, None
        raw = np.asarray(out)  # the frame gate's statistics, channels in the label set's order
        raw = raw.transpose(0, 3, 1, 2) if self.contract.output_layout == "nhwc" else raw
        return probs, frame_tap(raw[:, self._order], outs[1:] or None,
                                probabilities=self.contract.output == "probabilities")

    def predict_frame(self, rgb: np.ndarray, *, stats: bool = False) -> np.ndarray | FramePass:
        """(C, h, w) float32 probabilities at the working resolution of an (H, W, 3) uint8 frame; with ``stats`` a
        :class:`~el.segmentation.frame_tap.FramePass` of them and the pass's statistics."""
        check_rgb(rgb, "frame", min_size=MIN_SIZE)
        w, h = self.working_size(rgb.shape[1], rgb.shape[0])
        if (rgb.shape[1], rgb.shape[0]) != (w, h):
            rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
        probs, tap = self._run(check_rgb(rgb, "frame at working resolution", min_size=MIN_SIZE), "frame", stats)
        return FramePass(probs, tap) if stats else probs

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        """(C, h, w) float32 probabilities of an (h, w, 3) uint8 patch at its own resolution."""
        return self._run(check_rgb(rgb_patch, "patch", min_size=MIN_SIZE), "patch")[0]

    def predict_patches(self, patches: list[np.ndarray]) -> list[np.ndarray]:
        """:meth:`predict_patch` of each patch, in order. Patches fed to the network at one size (the contract's
        ``net_size``: their own, their padded or the fixed size) share one pass when the file's batch axis is free;
        the contract pads or resizes each patch as it does alone, so each keeps its own scores."""
        for i, p in enumerate(patches):
            check_rgb(p, f"patch {i}", min_size=MIN_SIZE)
        if not self._batch_free:
            return [self._run(p, "patch")[0] for p in patches]
        groups: dict[tuple[int, int], list[int]] = {}
        for i, p in enumerate(patches):
            groups.setdefault(self.contract.net_size(p.shape[1], p.shape[0]), []).append(i)
        out: list[np.ndarray | None] = [None] * len(patches)
        for idx in groups.values():
            checkpoint("patch segmentation")
            batch = np.concatenate([self.contract.to_input(patches[i]) for i in idx])
            raw = np.asarray(run_session(self._session, [self._output], {self._input: batch}, "patch segmentation")[0])
            if raw.ndim != 4 or raw.shape[0] != len(idx):
                raise ValueError(f"patches: the ONNX output is {raw.shape}, expected a batch of {len(idx)}")
            for j, i in enumerate(idx):
                h, w = patches[i].shape[:2]
                probs = self.contract.to_probs(raw[j:j + 1], w, h, "patch")[self._order]
                out[i] = np.ascontiguousarray(probs, dtype=np.float32)
        return out  # type: ignore[return-value]

    def probe(self) -> None:
        """One tiny inference; a one-line WeightsError for an output of the wrong rank, shape, class count
        or with non-finite values (a file that cannot serve is refused at load, not at the first frame)."""
        w, h = self.contract.net_size(MIN_SIZE * 2, MIN_SIZE * 2)
        ramp = (np.arange(h * w * 3, dtype=np.int64).reshape(h, w, 3) * 37 % 256).astype(np.uint8)
        try:
            self._run(ramp, "probe")
        except ValueError as exc:
            raise WeightsError(f"{self.path}: refused: {exc}") from None
        except Exception as exc:  # ONNX Runtime's own errors (a contract the graph does not accept)
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise WeightsError(f"{self.path}: refused: a {w}x{h} probe under the contract failed: {first}") from None


def load_onnx_model(path: str | Path, *, contract: OnnxContract | dict[str, Any] | None = None,
                    labels: LabelSet | None = None, sha256: str | None = None, threads: int | None = None,
                    working_width: int = 1024, class_names: Sequence[str] | None = None) -> OnnxModel:
    """An ONNX file as a segmentation model, checked; every problem a one-line ``WeightsError``.

    ``contract`` None: the file's metadata (:data:`META_CONTRACT`); ``labels``: the system's label set, which
    the contract's classes must be; None: the network's own classes, the file's label set
    (:data:`META_LABELS`) when it carries one of the contract's classes, else :class:`OutputClasses` of the
    contract's ``class_names`` (to be mapped by a class map); ``sha256``: the file's identity must be it;
    ``threads``: ONNX Runtime's intra-op threads; ``working_width``: the frames' working resolution;
    ``class_names``: the output channels' names, replacing the contract's (a system file's ``[model] classes``
    over the file's metadata). The file
    (and its external data) is read once, checked, and the session built from those bytes; one probe inference
    (:meth:`OnnxModel.probe`) refuses an output of the wrong class count, rank or shape, or not finite.
    """
    data, digest = read_checked(path, sha256)
    session = open_session(data, path, threads)
    session_meta = metadata(session)
    if contract is None:
        contract = contract_from_metadata(session_meta, path)
    elif isinstance(contract, dict):
        try:
            contract = OnnxContract.from_dict(contract)
        except (TypeError, ValueError) as exc:
            raise WeightsError(f"{path}: {exc}") from None
    if class_names is not None:
        try:
            contract = replace(contract, class_names=tuple(class_names))
        except (TypeError, ValueError) as exc:
            raise WeightsError(f"{path}: {exc}") from None
    classes: LabelSet | OutputClasses = labels if labels is not None else _own_classes(session_meta, contract, path)
    model = OnnxModel(path, contract, classes, digest, threads=threads, working_width=working_width,
                      session=session)
    model.probe()
    return model


def _own_classes(meta: dict[str, str], contract: OnnxContract, path: str | Path) -> LabelSet | OutputClasses:
    """The network's own classes: the file's label set when it carries one naming the contract's classes, else
    the contract's class names."""
    if META_LABELS in meta:
        try:
            carried = LabelSet.from_dict(json.loads(meta[META_LABELS]))
        except (TypeError, ValueError) as exc:
            raise WeightsError(f"{path}: metadata {META_LABELS!r}: {exc}") from None
        if set(carried.names) == set(contract.class_names):
            return carried
    return OutputClasses(Path(path).name, contract.class_names)
