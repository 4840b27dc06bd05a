"""Build the segmentation model a system file's ``[model]`` names, as its label set requires.

``model_source`` (``assurance.system.build``) is the model as data (kind, path, expected SHA-256, ONNX
contract, class map, label set): picklable, recorded in a campaign's manifest, rebuilt in each worker by
``build_model``. The model must end up producing the system's label set: the network's own classes, or a
``class_map`` onto the system's; anything else is refused before any frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from el.errors import WeightsError
from el.labels import LabelSet


def build_model(source: Mapping[str, Any], *, threads: int | None = None, device: str = "cpu",
                working_width: int | None = None) -> Any:
    """The model of ``source``; ``WeightsError`` naming the system file and the problem."""
    from el.segmentation.contract import labels_of
    from el.segmentation.factory import load_model

    labels = LabelSet.from_dict(dict(source["labels"]))
    kind, where = source["kind"], source.get("system", "system file")
    if kind == "onnx":
        model = _onnx(source, labels if not source.get("class_map") else None, threads)
    else:
        spec = {"builtin": None, "pt": source.get("path"), "plugin": source.get("name")}[kind]
        model = load_model(spec, threads=threads, device=device, working_width=working_width)
        _check_hash(model, source, where)
    class_map = source.get("class_map")
    if class_map:
        from el.segmentation.class_map import MappedModel

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
    from el.segmentation.factory import load_model

    return load_model(spec, threads=threads, device=device, working_width=working_width)


def _onnx(source: Mapping[str, Any], labels: LabelSet | None, threads: int | None) -> Any:
    try:
        from el.segmentation.onnx_model import OnnxContract, load_onnx_model
    except ImportError as exc:  # pragma: no cover - the module ships with the package
        raise WeightsError(f"ONNX models are not supported by this installation: {exc}") from None
    contract = source.get("onnx")
    kwargs: dict[str, Any] = {"sha256": source.get("sha256"), "threads": threads}
    if contract:
        kwargs["contract"] = OnnxContract.from_dict(dict(contract))
    if labels is not None:
        kwargs["labels"] = labels
    return load_onnx_model(source["path"], **kwargs)


def _check_hash(model: Any, source: Mapping[str, Any], where: str) -> None:
    """A plugin's reported weights hash must be the one the system file states (files were checked at load)."""
    from el.segmentation.contract import weights_sha256_of

    want = source.get("sha256")
    if want and source["kind"] == "plugin":
        have = weights_sha256_of(model)
        if have != want:
            raise WeightsError(f"{where}: model.sha256: the model {source.get('name')!r} reports weights {have}, "
                               f"the system file states {want}")
