"""The monitor registry: every runtime monitor by name, built in or from a plugin package.

In the spirit of imagecorruptions' ``corruption_dict``: one table from a name to what builds it.
A monitor is one module and one registration line, either in :data:`BUILTIN` below (a monitor of
this repository) or, for a package outside it, in that package's ``pyproject.toml``::

    [project.entry-points."uav_el.monitors"]
    toy = "toy_monitor:ToyMonitor"

The registered object is a :class:`el.monitors.base.Monitor` subclass (or a :class:`MonitorEntry`).
Its constructor takes its parameters as keywords plus ``margin``, ``max_side``, ``clock`` and
``threshold``; the class attribute ``PARAMS`` maps each parameter name to a converter from the spec
string (``{"q": float}``) and ``REQUIRED`` names those without a default. Then ``toy:q=0.5`` works
wherever a monitor spec does: ``uav-el land --monitor``, ``uav-el campaign --monitors``,
``PipelineConfig(monitor=...)``.

The paper's monitors (``lhd``, ``lhd+ch``, ``lhd+mcd``, ``lhd+ch+mcd``) keep their own grammar
(``el.monitors.spec``) and are listed here for completeness.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

ENTRY_POINT_GROUP = "uav_el.monitors"

BUILTIN: dict[str, str] = {
    "msp": "el.monitors.softmax_scores:MSPMonitor",
    "entropy": "el.monitors.softmax_scores:EntropyMonitor",
    "energy": "el.monitors.softmax_scores:EnergyMonitor",
    "learned": "el.monitors.learned:LearnedMonitor",
    "verifier": "el.monitors.verifier:VerifierMonitor",
    "odin": "el.monitors.odin:ODINMonitor",
    "doctor": "el.monitors.doctor:DOCTORMonitor",
    "mahalanobis": "el.monitors.mahalanobis:MahalanobisMonitor",
    "gmm": "el.monitors.gmm:GMMMonitor",
    "outside_box": "el.monitors.outside_box:OutsideBoxMonitor",
}
"""Monitors of this repository: name -> ``module:Class`` (imported when first used)."""

PAPER_KINDS = ("lhd", "lhd+ch", "lhd+mcd", "lhd+ch+mcd")


@dataclass(frozen=True)
class MonitorEntry:
    """How to build a registered monitor: ``factory(**params, margin=, max_side=, clock=, threshold=)``."""

    name: str
    factory: Callable[..., Any]
    params: Mapping[str, Callable[[str], Any]] = field(default_factory=dict)
    required: tuple[str, ...] = ()
    source: str = "builtin"


_PLUGINS: dict[str, MonitorEntry | str] | None = None  # name -> entry, or the error that stopped it loading
_EXTRA: dict[str, MonitorEntry] = {}


def _entry(name: str, obj: Any, source: str) -> MonitorEntry:
    if isinstance(obj, MonitorEntry):
        return obj
    if not callable(obj):
        raise ValueError(f"monitor {name!r} ({source}) is not a Monitor class or MonitorEntry")
    return MonitorEntry(name, obj, dict(getattr(obj, "PARAMS", {})), tuple(getattr(obj, "REQUIRED", ())), source)


def _load(ref: str) -> Any:
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


def _plugins() -> dict[str, MonitorEntry | str]:
    """Entry points of the ``uav_el.monitors`` group, loaded once (a broken one is kept as its error)."""
    global _PLUGINS
    if _PLUGINS is None:
        found: dict[str, MonitorEntry | str] = {}
        for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
            try:
                found[ep.name.lower()] = _entry(ep.name.lower(), ep.load(), f"entry point {ep.value}")
            except Exception as exc:  # reported when the monitor is asked for, not at every import
                found[ep.name.lower()] = f"monitor plugin {ep.name!r} ({ep.value}) failed to load: " \
                                         f"{type(exc).__name__}: {exc}"
        _PLUGINS = found
    return _PLUGINS


def reload_plugins() -> None:
    """Forget the loaded entry points (after installing a plugin in a running process; tests)."""
    global _PLUGINS
    _PLUGINS = None


def register_monitor(name: str, factory: Callable[..., Any], *, params: Mapping[str, Callable[[str], Any]] | None
                     = None, required: tuple[str, ...] = ()) -> None:
    """Register a monitor in this process (what an entry point does for an installed package)."""
    key = name.lower()
    if key in PAPER_KINDS or key in BUILTIN or not key.isidentifier():
        raise ValueError(f"cannot register a monitor named {name!r} (taken, or not an identifier)")
    _EXTRA[key] = MonitorEntry(key, factory, dict(params or getattr(factory, "PARAMS", {})),
                               tuple(required or getattr(factory, "REQUIRED", ())), "register_monitor")


def unregister_monitor(name: str) -> None:
    _EXTRA.pop(name.lower(), None)


def monitor_names() -> list[str]:
    """Every monitor name: the paper's kinds, the built-ins, then plugins."""
    return [*PAPER_KINDS, *BUILTIN, *sorted(set(_EXTRA) | set(_plugins()))]


def monitor_entry(name: str) -> MonitorEntry:
    """The registry entry of a (non-paper) monitor name; ValueError naming the known ones."""
    key = name.lower()
    if key in BUILTIN:
        return _entry(key, _load(BUILTIN[key]), "builtin")
    if key in _EXTRA:
        return _EXTRA[key]
    found = _plugins().get(key)
    if isinstance(found, str):
        raise ValueError(found)
    if found is None:
        raise ValueError(f"unknown monitor {name!r} (registered: {', '.join(monitor_names())})")
    return found
