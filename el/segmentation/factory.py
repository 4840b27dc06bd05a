"""One factory for segmentation models: the shipped network, a project weights file, or a plugin.

A model spec is what a user writes in a command or a system file:

- None, ``""`` or ``"shipped"``: the shipped weights (``el/segmentation/weights/model.pt``);
- a path to a ``.pt`` weights file with its model card beside it (``uav-el train`` writes both);
- a path to an ``.onnx`` file: a network from elsewhere under ONNX Runtime, its input contract and label set
  read from the file's metadata (:func:`el.segmentation.onnx_model.load_onnx_model`; ``uav-el export-onnx``
  writes both; a file without them is declared in a system file, ``assurance.system``);
- ``NAME`` or ``NAME:ARG``: a factory registered in the ``uav_el.models`` entry-point group (a package's
  ``pyproject.toml``: ``[project.entry-points."uav_el.models"] mynet = "mypkg.models:build"``), called as
  ``factory(ARG or None, threads=..., device=...)``; it returns any object implementing
  :class:`el.segmentation.contract.SegmentationModel` (an ONNX runtime session wrapper, a remote
  accelerator, a torch module wrapped in :class:`~el.segmentation.inference.Segmenter`).

Weights files are SHA-256 checked against their card before ``torch.load(weights_only=True)``; every
problem raises ``WeightsError`` naming the file or the spec. Without torch (an optional heavy dependency: the
``train`` extra) the shipped network, or a ``.pt`` file with its export record, runs from its checked ONNX export
(:class:`el.segmentation.onnx_segmenter.OnnxSegmenter`, the same decisions); any other torch network is a
``TorchMissing`` naming the extra.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

from el.base import torch_extra
from el.base.errors import WeightsError
from el.segmentation.contract import OutputClasses, check_model
from el.segmentation.onnx_model import load_onnx_model
from el.segmentation.onnx_segmenter import OnnxSegmenter

ENTRY_POINT_GROUP = "uav_el.models"
SHIPPED = "shipped"
_NAME = re.compile(r"^[A-Za-z_][\w.-]*$")


def model_factories() -> dict[str, Any]:
    """The registered model factories: entry-point name -> entry point (loaded when used)."""
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


SHIPPED_KIND, FILE, PLUGIN = "shipped", "file", "plugin"


def model_kind(spec: str | Path | None) -> str:
    """What a spec names: the shipped weights, a weights file, or a model factory (registered or not).

    A registered name wins, whatever follows its colon (``onnx:/models/net.onnx``); a one-letter prefix is
    a drive letter, never a name.
    """
    if spec is None or str(spec) in ("", SHIPPED):
        return SHIPPED_KIND
    text = str(spec)
    name = text.partition(":")[0]
    if len(name) > 1 and _NAME.match(name) and name in model_factories():
        return PLUGIN
    if text.endswith((".pt", ".onnx")) or "/" in text or "\\" in text or Path(text).is_file():
        return FILE
    return PLUGIN


def is_weights_file(spec: str | Path) -> bool:
    """Whether a spec names a weights file, ``.pt`` or ``.onnx`` (not the shipped default, not a model factory)."""
    return model_kind(spec) == FILE


def is_onnx_file(spec: str | Path | None) -> bool:
    """Whether a spec names an ONNX file (a weights file ending in ``.onnx``)."""
    return spec is not None and model_kind(spec) == FILE and str(spec).lower().endswith(".onnx")


def load_model(spec: str | Path | None = None, *, threads: int | None = None, device: str = "cpu",
               working_width: int | None = None) -> Any:
    """The segmentation model a spec names (see the module docstring); ``WeightsError`` naming the problem.

    ``working_width``: the core model's working width, for a weights file (a plugin keeps its own).
    """
    kind = model_kind(spec)
    if kind == SHIPPED_KIND:
        return _segmenter(None, threads, device, working_width)
    if kind == FILE and is_onnx_file(spec):
        width = {} if working_width is None else {"working_width": working_width}
        model = load_onnx_model(spec, threads=threads, **width)  # type: ignore[arg-type]
        if isinstance(model.labels, OutputClasses):  # no label set says what its classes mean: no guessing
            raise WeightsError(f"{spec}: the network's classes {list(model.labels.names)} come with no label set "
                               "(the file's metadata has none): declare it in a system file ([labels], [model.onnx] "
                               "class_names and [model] class_map)")
        return model
    if kind == FILE:
        return _segmenter(spec, threads, device, working_width)
    name, _, arg = str(spec).partition(":")
    if not _NAME.match(name):
        raise WeightsError(f"model spec {str(spec)!r}: neither a .pt or .onnx file nor a registered model name")
    factories = model_factories()
    if name not in factories:
        known = ", ".join(sorted(factories)) or "none installed"
        raise WeightsError(f"model {name!r} is not registered in the {ENTRY_POINT_GROUP!r} entry points "
                           f"(registered: {known}); give a .pt weights file or install the plugin")
    try:
        factory: Callable[..., Any] = factories[name].load()
        model = factory(arg or None, threads=threads, device=device)
    except WeightsError:
        raise
    except (Exception, SystemExit) as exc:  # a plugin must not end the process: the caller fails safe
        raise WeightsError(f"model {name!r} ({factories[name].value}) failed to build: "
                           f"{type(exc).__name__}: {exc}") from exc
    try:
        return check_model(model, f"model {name!r}")
    except ValueError as exc:
        raise WeightsError(str(exc)) from None


def _segmenter(path: str | Path | None, threads: int | None, device: str, working_width: int | None) -> Any:
    """The ``Segmenter`` of a weights file (None: the shipped one); without torch (the optional heavy dependency, the
    ``train`` extra) its checked ONNX export under ONNX Runtime (``el.segmentation.onnx_segmenter``), same decisions."""
    width = {} if working_width is None else {"working_width": working_width}
    if not torch_extra.have_torch():  # looked up at each call (tests stand in for a light install through it)
        if device != "cpu":
            raise torch_extra.TorchMissing(torch_extra.missing_line(f"device {device!r}"))
        return OnnxSegmenter.load(path, threads=threads, **width)
    from el.segmentation.inference import Segmenter  # deferred: imports torch (the train extra); light installs lack it

    return Segmenter.load(path, threads=threads, device=device, **width)
