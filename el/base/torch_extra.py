"""torch, an optional heavy dependency: the ``train`` extra (``pip install 'uav-el-assurance[train]'``).

The deployed system runs the shipped network's ONNX export on ONNX Runtime (``el.segmentation.onnx_segmenter``), so a
base install flies without torch. What needs torch (training, MC dropout, ``.pt`` and torch-module networks, the trunk
study) imports it through :func:`require_torch`, which names the extra in one line when it is missing.
"""

from __future__ import annotations

import importlib.util
import sys
from typing import Any

from el.base.errors import WeightsError

TRAIN_EXTRA = "pip install 'uav-el-assurance[train]'"


class TorchMissing(WeightsError):
    """torch is needed and not installed (a ``WeightsError``: in flight the default action, with this reason)."""


def missing_line(what: str) -> str:
    """The one line that says what needs torch and how to get it."""
    return f"{what} needs torch, which is not installed (the base install runs the ONNX export): {TRAIN_EXTRA}"


def have_torch() -> bool:
    """Whether torch can be imported, without importing it (an import already tried and failed counts as absent)."""
    if "torch" in sys.modules:
        return sys.modules["torch"] is not None
    try:
        return importlib.util.find_spec("torch") is not None
    except (ImportError, ValueError):
        return False


def require_torch(what: str) -> Any:
    """The ``torch`` module, or :class:`TorchMissing` with :func:`missing_line` for ``what``."""
    try:
        import torch
    except ImportError:
        raise TorchMissing(missing_line(what)) from None
    return torch
