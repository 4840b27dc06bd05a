"""Which model capabilities a monitor needs, checked before any decision (docs/architecture.md section 1.4).

A model behind the segmentation seam may lack the optional capabilities of
:mod:`el.segmentation.contract` (an ONNX file offers none: no MC dropout, no trunk). A monitor needing one
would fail on every candidate; a campaign would lose every configuration of every task to that one
configuration. :func:`check_monitor_capabilities` refuses such a system when it is put together: the
campaign (``assurance.campaign.manifest.check_monitor_networks``, before the run folder exists) and the
pipeline (``el.pipeline.check_monitor_bindings``) call it where they check the monitor's network.
"""

from __future__ import annotations

from typing import Any

from el.segmentation.contract import MC_DROPOUT, TRUNK_FEATURES, has_capability

WHAT = {MC_DROPOUT: "MC dropout samples (mc_dropout)", TRUNK_FEATURES: "the network's trunk features (model.trunk)"}


def required_capabilities(monitor: Any) -> tuple[str, ...]:
    """The capabilities a monitor needs: its ``required_capabilities`` attribute when it declares one (a
    plugin), else MC dropout for the MCD monitors and for a learned monitor whose model reads MC samples."""
    declared = getattr(monitor, "required_capabilities", None)
    if declared is not None:
        return tuple(declared)
    from el.monitors.learned import LearnedMonitor
    from el.monitors.mcd import MCDMonitor

    if isinstance(monitor, MCDMonitor) or (isinstance(monitor, LearnedMonitor) and monitor.model.mcd_n > 0):
        return (MC_DROPOUT,)
    return ()


def _name(model: Any) -> str:
    where = getattr(model, "path", None)
    return type(model).__name__ + (f" ({where})" if where else "")


def check_monitor_capabilities(monitor: Any, model: Any) -> None:
    """Refuse a monitor needing what the model does not offer: one-line ValueError naming the monitor and the
    missing capability. ``monitor`` None: nothing to check."""
    if monitor is not None:
        for capability in required_capabilities(monitor):
            if not has_capability(model, capability):
                raise ValueError(f"monitor {monitor.name!r} needs {WHAT.get(capability, capability)}, which the "
                                 f"segmentation model {_name(model)} does not offer; choose a monitor without it")
