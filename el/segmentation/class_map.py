"""A network segmenting into another label set than the system's, seen through a class map (section 1.4).

:class:`MappedModel` wraps any :class:`el.segmentation.contract.SegmentationModel` whose classes differ
from the system's label set: each network class is mapped onto one system class (many-to-one allowed)
and the probabilities of the network classes mapped onto a system class are summed. So the shipped
UAVid network can be evaluated on data labelled with another palette, and a foreign network (another
class count) can drive this system. A one-to-one map (a renaming, another id order) gives the very same
probabilities, reordered: sums of one term are exact.

Capabilities pass through where the class map keeps their meaning: ``mc_dropout`` (each sample is
mapped), ``patch_trunk`` (the trunk is class-free; ``predict_patch`` and ``mc_dropout`` take its
``features=`` and map their output), the trunk features of the out-of-domain gate (``model.trunk``
and ``working_size``: class-free) and the frame pass's statistics a frame gate reads (``predict_frame(rgb,
stats=True)``: the network's own, in its own classes, like the gate fitted on it). Not passed: ``fast_mc``
(the chunked MC path reads the network's head directly and would bypass the map), so MC dropout goes
through the mapped ``mc_dropout`` in one draw: in flight, a large MCD ``n`` is not cut into budget-checked
chunks. ``network_classes``: the network's own class count (softmax scores are normalised by it).
``weights_sha256`` is the network's: records fitted on it stay bound to it. Beware that a record whose
features are per class (a learned monitor's per-class features, a softmax-embedding out-of-domain gate)
was fitted in the network's classes; the learned monitor refuses class names it does not know, a
softmax-embedding gate does not see the difference.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from el.classes.labels import LabelSet
from el.segmentation.contract import (
    FRAME_STATS,
    MC_DROPOUT,
    PATCH_TRUNK,
    check_model,
    has_capability,
    labels_of,
    segment_frame,
)
from el.segmentation.frame_tap import FramePass


def check_class_map(network: LabelSet, system: LabelSet, mapping: Mapping[str, str],
                    unreachable: Sequence[str] = ()) -> np.ndarray:
    """The system class id of each network class, (C_net,) int64, after checking ``mapping``.

    Every network class must be mapped, onto a system class; every system class must be reached or
    listed in ``unreachable`` (and not both). ValueError naming the class.
    """
    if not isinstance(mapping, Mapping):
        raise ValueError(f"class map: must be a mapping of network class -> system class, got {mapping!r}")
    unknown = [k for k in mapping if k not in network.ids]
    if unknown:
        raise ValueError(f"class map: {unknown[0]!r} is not a class of the network's label set "
                         f"{network.name!r} (classes: {', '.join(network.names)})")
    unmapped = [n for n in network.names if n not in mapping]
    if unmapped:
        raise ValueError(f"class map: network class {unmapped[0]!r} is not mapped onto a system class "
                         f"(unmapped: {', '.join(unmapped)}; system classes: {', '.join(system.names)})")
    for k, v in mapping.items():
        if v not in system.ids:
            raise ValueError(f"class map: {k!r} -> {v!r}: {v!r} is not a class of the system's label set "
                             f"{system.name!r} (classes: {', '.join(system.names)})")
    reached = set(mapping.values())
    if isinstance(unreachable, str):
        raise ValueError(f"class map: unreachable must be a list of system class names, got {unreachable!r}")
    for u in unreachable:
        if u not in system.ids:
            raise ValueError(f"class map: unreachable {u!r} is not a class of the system's label set {system.name!r}")
        if u in reached:
            onto = sorted(k for k, v in mapping.items() if v == u)
            raise ValueError(f"class map: system class {u!r} is listed unreachable but {onto} map onto it")
    missing = [n for n in system.names if n not in reached and n not in unreachable]
    if missing:
        raise ValueError(f"class map: system class {missing[0]!r} is reached by no network class (list it "
                         f"as unreachable if the network cannot predict it; unreached: {', '.join(missing)})")
    return np.array([system.ids[mapping[n]] for n in network.names], dtype=np.int64)


def map_probabilities(probs: np.ndarray, target: np.ndarray, num_classes: int, *, axis: int = 0) -> np.ndarray:
    """Sum the class planes of ``probs`` along ``axis`` onto ``num_classes`` classes (``target[c]``: the class
    network class c goes to); classes nobody reaches are 0. float32, same shape but that axis."""
    probs = np.asarray(probs)
    if probs.ndim <= axis or probs.shape[axis] != len(target):
        raise ValueError(f"class map: the network gave {getattr(probs, 'shape', None)} scores, expected "
                         f"{len(target)} classes on axis {axis}")
    moved = np.moveaxis(probs, axis, 0)
    out = np.zeros((num_classes, *moved.shape[1:]), dtype=np.float32)
    for c, s in enumerate(target):
        out[s] += moved[c]  # one term per class for a renaming: exact
    return np.moveaxis(out, 0, axis)


class _MappedCall:
    """A network method whose class axis is mapped; it shows the method's own signature (keywords it takes)."""

    def __init__(self, fn: Callable[..., np.ndarray], owner: MappedModel, axis: int) -> None:
        self._fn, self._owner, self._axis = fn, owner, axis

    @property
    def __signature__(self) -> inspect.Signature:
        return inspect.signature(self._fn)

    def __call__(self, *args: Any, **kwargs: Any) -> np.ndarray:
        return self._owner._map(self._fn(*args, **kwargs), self._axis)


class MappedModel:
    """``model`` (a SegmentationModel over its own label set) seen in the system's label set ``labels``.

    ``mapping``: network class name -> system class name, every network class mapped (many-to-one
    allowed); ``unreachable``: system classes no network class maps onto (their probability is 0).
    Implements the SegmentationModel protocol (``predict_frame``, ``predict_patch``, ``labels`` = the
    system set, ``weights_sha256`` = the network's) and passes through ``mc_dropout``, ``patch_trunk``
    and the trunk features where the network has them (module docstring). ValueError naming the class
    for a bad map.

    Examples
    --------
    >>> from el.classes.labels import UAVID
    >>> m = MappedModel(network, {n: n for n in UAVID.names}, UAVID)  # doctest: +SKIP
    """

    def __init__(self, model: Any, mapping: Mapping[str, str], labels: LabelSet,
                 *, unreachable: Sequence[str] = ()) -> None:
        check_model(model, "mapped network")
        if not isinstance(labels, LabelSet):
            raise ValueError(f"class map: labels must be a LabelSet, got {type(labels).__name__}")
        self.network = model
        self.network_labels = labels_of(model)
        self.labels = labels
        self.mapping = dict(mapping)
        self.unreachable = tuple(unreachable)
        self.target = check_class_map(self.network_labels, labels, self.mapping, self.unreachable)

    def _map(self, probs: np.ndarray, axis: int) -> np.ndarray:
        return map_probabilities(probs, self.target, self.labels.num_classes, axis=axis)

    @property
    def weights_sha256(self) -> str | None:
        """The network's identity (the class map does not change which network runs)."""
        return getattr(self.network, "weights_sha256", None)

    @property
    def network_classes(self) -> int:
        """How many classes the network itself outputs (before the map): what its softmax scores are normalised by."""
        return int(self.network_labels.num_classes)

    @property
    def frame_stats(self) -> bool:
        """Whether the network returns its frame pass's statistics (``FRAME_STATS``): the map passes them through
        untouched, in the network's own classes."""
        return has_capability(self.network, FRAME_STATS)

    def predict_frame(self, rgb: np.ndarray, *, stats: bool = False) -> np.ndarray | FramePass:
        """The network's frame probabilities summed onto the system's classes: (C_sys, h, w) float32; with ``stats``
        a ``FramePass`` of them and the network's statistics of the pass (None from a network without them)."""
        probs, found = segment_frame(self.network, rgb, stats=stats)
        return FramePass(self._map(probs, 0), found) if stats else self._map(probs, 0)

    def predict_patch(self, rgb_patch: np.ndarray, **kwargs: Any) -> np.ndarray:
        """The network's patch probabilities summed onto the system's classes (``features=`` passed on)."""
        return self._map(self.network.predict_patch(rgb_patch, **kwargs), 0)

    @property
    def mc_dropout(self) -> _MappedCall:
        """The network's MC-dropout samples (n, C_net, h, w) mapped sample by sample (AttributeError without)."""
        if not has_capability(self.network, MC_DROPOUT):
            raise AttributeError(f"{type(self.network).__name__} offers no mc_dropout")
        return _MappedCall(self.network.mc_dropout, self, 1)

    @property
    def patch_trunk(self) -> Callable[[np.ndarray], Any]:
        """The network's class-free patch trunk (AttributeError without)."""
        if not has_capability(self.network, PATCH_TRUNK):
            raise AttributeError(f"{type(self.network).__name__} offers no patch_trunk")
        return self.network.patch_trunk  # type: ignore[no-any-return]

    @property
    def model(self) -> Any:
        """The network's module, for its class-free trunk (the out-of-domain gate's embedding)."""
        inner = getattr(self.network, "model", None)
        if inner is None:
            raise AttributeError(f"{type(self.network).__name__} exposes no model")
        return inner

    @property
    def device(self) -> Any:
        """Where the network runs (read with the trunk features)."""
        return getattr(self.network, "device", "cpu")

    def working_size(self, width: int, height: int) -> tuple[int, int]:
        """The network's working size for a frame (read with the trunk features)."""
        return self.network.working_size(width, height)  # type: ignore[no-any-return]

    def __repr__(self) -> str:
        return (f"MappedModel({type(self.network).__name__} {self.network_labels.name!r} -> "
                f"{self.labels.name!r})")
