"""Build the segmentation model a system file's ``[model]`` names, as its label set requires.

``model_source`` (``assurance.system.build``) is the model as data (kind, path, expected identity, ONNX
contract, output channels' names, class map, working width, label set): picklable, recorded in a campaign's
manifest, rebuilt in each worker by ``build_model``. The model must end up producing the system's label set:
the network's own classes, or a ``class_map`` from its output classes (``[model] classes`` or
``[model.onnx] class_names``) onto the system's; anything else is refused before any frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from el.base.errors import WeightsError
from el.classes.labels import LabelSet
from el.segmentation import factory
from el.segmentation.class_map import MappedModel
from el.segmentation.contract import OutputClasses, labels_of, weights_sha256_of
from el.segmentation.onnx_model import OnnxContract, load_onnx_model


def build_model(source: Mapping[str, Any], *, threads: int | None = None, device: str = "cpu",
                working_width: int | None = None) -> Any:
    """The model of ``source``; ``WeightsError`` naming the system file and the problem. ``working_width``
    (a command's option) wins over the source's (``[model] working_width``)."""
    labels = LabelSet.from_dict(dict(source["labels"]))
    kind, where = source["kind"], source.get("system", "system file")
    width = working_width if working_width is not None else source.get("working_width")
    class_map = source.get("class_map")
    if kind == "onnx":
        model = _onnx(source, None if class_map else labels, threads, width)
    else:
        spec = {"builtin": None, "pt": source.get("path"), "plugin": source.get("name")}[kind]
        model = factory.load_model(spec, threads=threads, device=device, working_width=width)
        _check_hash(model, source, where)
        _check_width(model, source, where, width)
        model = _named(model, source, where)
    own = labels_of(model)
    if not class_map and isinstance(own, OutputClasses) and set(own.names) == set(labels.names):
        class_map = {n: n for n in own.names}  # named channels that are the system's classes, in another order
    if class_map:
        try:
            model = MappedModel(model, dict(class_map), labels, unreachable=tuple(source.get("unreachable") or ()))
        except ValueError as exc:
            raise WeightsError(f"{where}: model.class_map: {exc}") from None
    have = labels_of(model)
    if have != labels:
        raise WeightsError(f"{where}: the model produces the classes {', '.join(have.names)} ({have.name}), the "
                           f"system's label set is {', '.join(labels.names)} ({labels.name}); map them with "
                           "[model] class_map")
    return model


def load_model_spec(spec: Any, *, threads: int | None = None, device: str = "cpu",
                    working_width: int | None = None) -> Any:
    """Load a model spec: None (the shipped network), a ``--model`` string (``el.segmentation.factory``), or a
    system file's model source (a mapping, :func:`build_model`)."""
    if isinstance(spec, Mapping):
        return build_model(spec, threads=threads, device=device, working_width=working_width)
    return factory.load_model(spec, threads=threads, device=device, working_width=working_width)


def _onnx(source: Mapping[str, Any], labels: LabelSet | None, threads: int | None, width: int | None) -> Any:
    """An ONNX model: its contract from the file's ``[model.onnx]`` (its channels named there or by
    ``[model] classes``) or the file's metadata; the system's ``labels``, or None for its own classes (a map)."""
    where = source.get("system", "system file")
    contract = dict(source.get("onnx") or {})
    kwargs: dict[str, Any] = {"sha256": source.get("sha256"), "threads": threads, "labels": labels,
                              "class_names": source.get("classes")}
    if width is not None:
        kwargs["working_width"] = int(width)
    if contract:
        contract.setdefault("class_names", source.get("classes"))
        try:
            kwargs["contract"] = OnnxContract.from_dict(contract)
        except (TypeError, ValueError) as exc:
            raise WeightsError(f"{where}: model.onnx: {exc}") from None
    return load_onnx_model(source["path"], **kwargs)


def _check_hash(model: Any, source: Mapping[str, Any], where: str) -> None:
    """A plugin's reported weights hash must be the one the system file states (files were checked at load)."""
    want = source.get("sha256")
    if want and source["kind"] == "plugin":
        have = weights_sha256_of(model)
        if have != want:
            raise WeightsError(f"{where}: model.sha256: the model {source.get('name')!r} reports weights {have}, "
                               f"the system file states {want}")


def _check_width(model: Any, source: Mapping[str, Any], where: str, width: int | None) -> None:
    """A plugin keeps its own working width: it must be the system's (else every decision would be a fault)."""
    size = getattr(model, "working_size", None)
    if width is None or source["kind"] != "plugin" or not callable(size):
        return
    have = int(size(3840, 2160)[0])
    if have != int(width):
        raise WeightsError(f"{where}: model.working_width: the model {source.get('name')!r} works at {have} px "
                           f"wide, the system's working width is {width}")


def _named(model: Any, source: Mapping[str, Any], where: str) -> Any:
    """``[model] classes`` for a model that is not ONNX: the names of its output channels. A model that states
    its label set must have these classes in this order; one that states none gets them."""
    classes = source.get("classes")
    if not classes:
        return model
    own = getattr(model, "labels", None)
    if own is not None:
        if tuple(own.names) != tuple(classes):
            raise WeightsError(f"{where}: model.classes: the model's output channels are {', '.join(own.names)} "
                               f"({own.name}), not {', '.join(classes)}")
        return model
    return NamedChannels(model, OutputClasses(str(source.get("name") or source["kind"]), tuple(classes)))


class NamedChannels:
    """A model that does not say its classes, with the output channels' names a system file gives it
    (``labels``, :class:`el.segmentation.contract.OutputClasses`); everything else is the model's."""

    def __init__(self, model: Any, labels: Any) -> None:
        self.network, self.labels = model, labels

    def predict_frame(self, rgb: Any, **kwargs: Any) -> Any:
        """The model's frame probabilities, unchanged; ``stats=True`` passed on where the model has the frame
        statistics capability (``el.segmentation.contract.FRAME_STATS``, which this wrapper forwards): a frame gate
        needs them."""
        return self.network.predict_frame(rgb, **kwargs)

    def predict_patch(self, rgb_patch: Any, **kwargs: Any) -> Any:
        """The model's patch probabilities, unchanged."""
        return self.network.predict_patch(rgb_patch, **kwargs)

    def __getattr__(self, name: str) -> Any:
        if name in ("network", "labels") or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.network, name)
