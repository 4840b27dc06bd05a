"""Which model capabilities a monitor needs, checked before any decision (docs/architecture.md section 1.4).

A model behind the segmentation seam may lack the optional capabilities of
:mod:`el.segmentation.contract` (an ONNX file offers none: no MC dropout, no trunk). A monitor needing one
would fail on every candidate; a campaign would lose every configuration of every task to that one
configuration. :func:`check_monitor_capabilities` refuses such a system when it is put together:
``el.monitors.build_monitor(..., model=)`` when it builds the monitor, the campaign
(``assurance.campaign.manifest.check_monitor_networks``, before the run folder exists) and the pipeline
(``el.flight.pipeline.check_monitor_bindings``) where they check the monitor's network. The refusal is a
:class:`MonitorSupportError` naming the monitor's spec and, in user terms, what the model is.
"""

from __future__ import annotations

from typing import Any

from el.base.errors import UavElError
from el.monitors.learned import LearnedMonitor
from el.monitors.mcd import MCDMonitor
from el.segmentation.contract import MC_DROPOUT, TRUNK_FEATURES, has_capability

WHAT = {MC_DROPOUT: "MC dropout samples (mc_dropout)", TRUNK_FEATURES: "the network's trunk features (model.trunk)"}
NEEDS = {MC_DROPOUT: "MC dropout: a torch network with dropout layers (nn.Dropout, nn.Dropout2d, ...)"}
"""What a capability asks of the user's network, in their terms (:data:`WHAT` for the others)."""


class MonitorSupportError(UavElError, ValueError):
    """A monitor that cannot run on this label set or segmentation model; one line naming the monitor's spec.

    Raised when the monitor is built (never per frame), so a system or campaign is refused before any
    decision; the caller adds where the monitor was asked for (the system file)."""


def required_capabilities(monitor: Any) -> tuple[str, ...]:
    """The capabilities a monitor needs: its ``required_capabilities`` attribute when it declares one (a
    plugin), else MC dropout for the MCD monitors and for a learned monitor whose model reads MC samples."""
    declared = getattr(monitor, "required_capabilities", None)
    if declared is not None:
        return tuple(declared)

    if isinstance(monitor, MCDMonitor) or (isinstance(monitor, LearnedMonitor) and monitor.model.mcd_n > 0):
        return (MC_DROPOUT,)
    return ()


def _inner(model: Any) -> Any:
    """The network a class-mapped model (``el.segmentation.class_map.MappedModel``) wraps; None for another."""
    inner = getattr(model, "network", None)
    return inner if inner is not None and inner is not model and hasattr(model, "network_labels") else None


def mapped_network_classes(model: Any) -> int | None:
    """The class count of the network a class-mapped model wraps (its own softmax's); None for another model."""
    inner = _inner(model)
    return None if inner is None else int(model.network_labels.num_classes)


def model_kind(model: Any) -> str:
    """What a segmentation model is, in user terms: an ONNX network, a torch network (with or without dropout
    layers), a class-mapped one (and what it maps), or a model of a plugin (its class)."""
    inner = _inner(model)
    if inner is not None:
        return f"a class-mapped network (model.class_map) over {model_kind(inner)}"
    name = type(model).__name__
    if name == "OnnxModel":
        return "an ONNX network, which runs without dropout"
    if name == "OnnxSegmenter":  # the base install: torch, which runs MC dropout, is the train extra
        return ("the shipped network's ONNX export, run without torch (MC dropout needs torch: pip install "
                "'uav-el-assurance[train]')")
    has_dropout = getattr(model, "has_dropout", None)
    if has_dropout is not None:
        return "a torch network " + ("with dropout layers" if has_dropout else "without dropout layers")
    return f"a model of class {name}"


def offers(model: Any, capability: str) -> bool:
    """Whether ``model`` really offers ``capability``: it has the method, and for MC dropout a torch network
    has dropout layers (a class-mapped model: the network it maps)."""
    if not has_capability(model, capability):
        return False
    if capability != MC_DROPOUT:
        return True
    inner = _inner(model)
    if inner is not None:
        return offers(inner, capability)
    return bool(getattr(model, "has_dropout", True))  # a plugin's mc_dropout is taken at its word


def _where(model: Any) -> str:
    where = getattr(model, "path", None) or getattr(_inner(model), "path", None)
    return f" ({where})" if where else ""


def check_monitor_capabilities(monitor: Any, model: Any) -> None:
    """Refuse a monitor needing what the model does not offer: a one-line :class:`MonitorSupportError`
    naming the monitor's spec, what it needs and what the model is. ``monitor`` None: nothing to check."""
    if monitor is None:
        return
    for capability in required_capabilities(monitor):
        if not offers(model, capability):
            need = NEEDS.get(capability) or WHAT.get(capability, capability)
            raise MonitorSupportError(
                f"monitor {monitor.name!r} needs {need}; the segmentation model is {model_kind(model)}"
                f"{_where(model)}; choose a monitor without it")
