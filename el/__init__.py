"""Emergency-landing flight code: a camera frame in, a landing decision out (docs/flight-api.md).

The public flight API is ``__all__`` below, importable from ``el`` itself (``from el import EmergencyLanding``); each
name is loaded on first use, so ``import el`` stays light. The modules sit in one folder per layer, bottom first:
``base`` -> ``classes`` -> ``geometry`` -> ``landing`` -> ``segmentation`` -> ``monitors`` -> ``flight``
(docs/architecture.md section 1.1); a module imports only from its layer or below. The flat paths of earlier
releases (``el.pipeline``, ``el.camera``, ...) still import, as the very same modules (:data:`MOVED`).

This package never imports ``assurance`` (the test harness).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
from typing import Any

__version__ = "0.1.0"

API: dict[str, str] = {
    "EmergencyLanding": "el.flight.pipeline", "PipelineConfig": "el.flight.pipeline", "FrameFile": "el.flight.pipeline",
    "decide": "el.flight.pipeline", "DEPLOYED_MONITOR": "el.flight.pipeline", "FlightLog": "el.flight.flightlog",
    "Decision": "el.base.decision", "Candidate": "el.base.decision", "Disc": "el.base.decision",
    "MonitorVerdict": "el.base.decision", "UavElError": "el.base.errors", "LabelSet": "el.classes.labels",
    "UAVID": "el.classes.labels", "load_label_set": "el.classes.labels", "Intrinsics": "el.geometry.camera",
    "Pose": "el.geometry.camera", "SafetyParams": "el.geometry.camera", "CoreConfig": "el.geometry.config",
    "OperatingDomain": "el.geometry.odd", "Monitor": "el.monitors", "build_monitor": "el.monitors",
    "GateFile": "el.monitors.frame_gate",
    "load_model": "el.segmentation", "read_image": "el.base.imageio",
}
"""Each public name -> the module defining it."""

__all__ = sorted(API)

MOVED: dict[str, str] = {
    **{f"el.{m}": f"el.base.{m}" for m in ("errors", "rgb", "imageheader", "imageio", "userfiles", "hashing",
                                           "records", "safeyaml", "torch_extra", "deadline", "decision")},
    **{f"el.{m}": f"el.classes.{m}" for m in ("name_profile", "class_names", "label_tables", "labels")},
    **{f"el.{m}": f"el.geometry.{m}" for m in ("camera", "config", "odd", "discs")},
    **{f"el.{m}": f"el.landing.{m}" for m in ("regions", "representatives", "forbidden", "ranking", "candidates",
                                              "core")},
    "el.walk": "el.monitors.walk",
    **{f"el.{m}": f"el.flight.{m}" for m in ("kernel", "pipeline", "flightlog")},
}
"""The flat module paths of earlier releases -> where each module lives now; importing the old path gives the same
module object (a user's ``from el.pipeline import EmergencyLanding`` keeps working)."""


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use (PEP 562)."""
    module = API.get(name)
    if module is None:
        raise AttributeError(f"module 'el' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolves an old flat path (:data:`MOVED`) to the module at its new place, as that same object."""

    def __init__(self) -> None:
        self._specs: dict[str, Any] = {}

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> Any:
        module = importlib.import_module(MOVED[spec.name])
        self._specs[module.__name__] = module.__spec__
        return module

    def exec_module(self, module: Any) -> None:
        """Nothing to run (the module ran at its own path); the import machinery set ``__spec__`` to the alias's,
        so the module's own is put back."""
        module.__spec__ = self._specs[module.__name__]


if not any(isinstance(f, _Alias) for f in sys.meta_path):
    sys.meta_path.append(_Alias())
