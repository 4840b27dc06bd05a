"""Small formatting helpers of the evidence report: the templates get finished strings, never numbers."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from assurance import requirements as rq

STATE_CLASS = {rq.VERIFIED: "verified", rq.FAILED: "failed", rq.NOT_VERIFIED: "not-verified"}
STATUS_CLASS = {rq.PASS: "verified", rq.FAIL: "failed", rq.INSUFFICIENT: "not-verified"}
STATUS_TEXT = {rq.PASS: "pass", rq.FAIL: "fail", rq.INSUFFICIENT: "insufficient evidence"}


def to_float(v: Any) -> float:
    """A float, NaN when ``v`` is not a number."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def fmt(v: Any, digits: int = 3) -> str:
    """A number with ``digits`` decimals, 'n/a' when undefined."""
    x = to_float(v)
    return f"{x:.{digits}f}" if math.isfinite(x) else "n/a"


def pct(v: Any, digits: int = 1) -> str:
    """A share as a percentage with ``digits`` decimals, 'n/a' when undefined."""
    x = to_float(v)
    return f"{100 * x:.{digits}f}%" if math.isfinite(x) else "n/a"


def ci(row: Mapping[str, Any], name: str, digits: int) -> str:
    """The 95% interval ``[lo, hi]`` of a table row's figure ``name`` (empty when undefined)."""
    lo, hi = to_float(row.get(f"{name}_lo95")), to_float(row.get(f"{name}_hi95"))
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return ""
    return f"[{lo:.{digits}f}, {hi:.{digits}f}]"


def jsonable(obj: Any) -> Any:
    """``obj`` with plain JSON types only (NaN and infinities as None, NumPy scalars as Python ones)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj
