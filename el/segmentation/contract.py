"""What the flight code needs from a segmentation model: the one typed seam a user's network plugs into.

A model maps a full-resolution RGB frame to class probabilities over its system's label set at the
working resolution, and a full-resolution patch to probabilities at the patch's own resolution. It may
offer capabilities that some monitors need (MC dropout for MCD, a trunk shared between calls for
faster campaigns, trunk features, a frame pass's statistics for the frame gate); a monitor or gate that
needs a missing one is refused when the system is built, which the decision loop turns into the default
action. :class:`el.segmentation.Segmenter` (any ``torch.nn.Module``) is the built-in implementation;
:func:`el.segmentation.factory.load_model` builds one from a spec.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from el.base.records import weights_sha256_of  # noqa: F401  (re-exported: part of the seam)
from el.classes.labels import UAVID, LabelSet
from el.segmentation.frame_tap import FramePass

MC_DROPOUT = "mc_dropout"
"""Capability ``mc_dropout(rgb_patch, n, keep_prob, seed, *, features=None, window=None) -> (n, C, h, w)``:
seeded, prefix-consistent samples with dropout active (see ``el.monitors.base.PatchSegmenter``)."""
PATCH_TRUNK = "patch_trunk"
"""Capability ``patch_trunk(rgb_patch)``: the deterministic part of the network on a patch, computed once
and passed as ``features=`` to ``predict_patch`` and ``mc_dropout`` (None when the network has no split)."""
TRUNK_FEATURES = "trunk"
"""Capability: the network's trunk (``model.trunk``) and ``working_size(W, H)``, read by the out-of-domain
gate's trunk embedding."""
FRAME_STATS = "frame_stats"
"""Capability ``predict_frame(rgb, *, stats=True) -> (probs, stats)``: the frame's probabilities with the statistics of
the same pass (:class:`el.segmentation.frame_tap.FramePass`; ``stats`` a ``FrameTap`` or None), read by a frame gate.
A model declares it with the attribute ``frame_stats = True``; :func:`segment_frame` asks for them."""
CAPABILITIES = (MC_DROPOUT, PATCH_TRUNK, TRUNK_FEATURES, FRAME_STATS)


@runtime_checkable
class SegmentationModel(Protocol):
    """The segmentation seam: frame and patch in, class probabilities (C, h, w) out, C = the label set's size.

    ``predict_frame(rgb)``: (H, W, 3) uint8 frame -> (C, h, w) float32 probabilities at the working
    resolution ``(w, h) = working_size(W, H)``. ``predict_patch(rgb_patch)``: (h, w, 3) uint8 -> (C, h, w)
    at the patch's resolution, deterministic. Optional attributes, read with :func:`labels_of` and
    :func:`weights_sha256_of`: ``labels`` (a :class:`el.classes.labels.LabelSet`; UAVid when absent) and
    ``weights_sha256`` (the identity cards and fitted monitors are bound to; None when absent). A model offering
    :data:`FRAME_STATS` also takes ``predict_frame(rgb, stats=True)`` and returns ``(probs, stats)``.
    """

    def predict_frame(self, rgb: np.ndarray) -> np.ndarray: ...

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class OutputClasses:
    """A network's own output classes known only by name, in channel order: no colours, no forbidden/safe split,
    so never a system's label set; a class map (``el.segmentation.class_map.MappedModel``) maps them onto one.
    A user's network states them (an ONNX contract's ``class_names``, a system file's ``[model] classes``)."""

    name: str
    names: tuple[str, ...]
    ids: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        names = tuple(self.names) if isinstance(self.names, (list, tuple)) else ()
        if not names or not all(isinstance(n, str) and n.strip() for n in names) or len(set(names)) != len(names):
            raise ValueError(f"output classes of {self.name}: distinct non-empty names expected, got {self.names!r}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "ids", {n: i for i, n in enumerate(names)})

    @property
    def num_classes(self) -> int:
        """How many output channels."""
        return len(self.names)


def labels_of(model: Any) -> LabelSet | OutputClasses:
    """The classes a model segments into: its label set, or its output classes by name (:class:`OutputClasses`)
    when only a class map gives them a meaning; UAVid for a model that does not say."""
    labels = getattr(model, "labels", None)
    return UAVID if labels is None else labels


def has_capability(model: Any, capability: str) -> bool:
    """Whether a model offers an optional capability (:data:`CAPABILITIES`)."""
    if capability not in CAPABILITIES:
        raise ValueError(f"unknown capability {capability!r}; known: {', '.join(CAPABILITIES)}")
    if capability == TRUNK_FEATURES:
        return callable(getattr(getattr(model, "model", None), "trunk", None))
    if capability == FRAME_STATS:
        return getattr(model, FRAME_STATS, False) is True
    return callable(getattr(model, capability, None))


def segment_frame(model: Any, rgb: np.ndarray, *, stats: bool = False) -> FramePass:
    """``model``'s probabilities of a frame and, with ``stats``, the statistics of the same pass (:data:`FRAME_STATS`).
    A model without that capability is asked for the probabilities alone: its statistics are None, and a frame gate
    cannot score the frame (``FrameGate.score`` refuses it: a fault of the decision)."""
    if not (stats and has_capability(model, FRAME_STATS)):
        return FramePass(model.predict_frame(rgb), None)
    probs, found = model.predict_frame(rgb, stats=True)
    return FramePass(probs, found)


def check_model(model: Any, what: str = "segmentation model") -> Any:
    """``model`` if it implements :class:`SegmentationModel`, else a ValueError naming what is missing."""
    missing = [m for m in ("predict_frame", "predict_patch") if not callable(getattr(model, m, None))]
    if missing:
        raise ValueError(f"{what} {type(model).__name__} lacks {', '.join(missing)} (see el.segmentation.contract)")
    return model
