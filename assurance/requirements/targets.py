"""The requirement targets: every number the requirement checks read, validated, and the texts rendered from them.

A target is a registry parameter (``parameters:`` of ``assurance/requirements.yaml``) that a user may set
without editing the registry: ``load_registry(targets={...})`` / ``Registry.with_targets``, the pytest option
``--uav-el-targets FILE.json`` or ``set_targets`` (docs/architecture.md 4.6). ``check_target`` says what each
one allows; ``render_text`` fills the requirement texts' placeholders (``{radius_m:g} m``, ``{confidence:pct}``)
with a small formatter that evaluates nothing: a placeholder is a parameter name, optionally ``.key`` into a
mapping parameter, and a format spec; anything else, or a name no parameter has, is a ``TargetError``.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import string
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from el.base import userfiles
from el.base.errors import UavElError


class TargetError(UavElError, ValueError):
    """A target override or a requirement-text placeholder is invalid; the message names the key and the value."""


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def _integer(value: Any) -> int | None:
    return None if isinstance(value, bool) or not isinstance(value, int) else int(value)


def _in(lo: float, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = True) -> Callable[[Any], Any]:
    def check(value: Any) -> float | None:
        v = _number(value)
        if v is None or (v <= lo if lo_open else v < lo) or (hi is not None and (v >= hi if hi_open else v > hi)):
            return None
        return v
    return check


def _int_at_least(lo: int) -> Callable[[Any], Any]:
    def check(value: Any) -> int | None:
        v = _integer(value)
        return v if v is not None and v >= lo else None
    return check


def _text(value: Any) -> str | None:
    return value.strip() if isinstance(value, str) and value.strip() else None


def _names(value: Any) -> list[str] | None:
    if not isinstance(value, list | tuple) or not value or not all(_text(v) for v in value):
        return None
    names = [v.strip() for v in value]
    return names if len(set(names)) == len(names) else None


def _pose_error(value: Any) -> dict[str, float] | None:
    if not isinstance(value, Mapping) or set(value) != {"height", "pitch"}:
        return None
    out = {k: _in(0.0, 1.0)(value[k]) for k in ("height", "pitch")}
    return None if None in out.values() else out  # type: ignore[return-value]


def _card(value: Any) -> str | None:
    return None if value is None else _text(value)


TARGETS: dict[str, tuple[str, Callable[[Any], Any]]] = {
    "deployed_monitor": ("a monitor configuration (a non-empty string, e.g. 'learned:walk=score')", _text),
    "required_perturbations": ("a non-empty list of distinct perturbation names", _names),
    "min_images_per_perturbation": ("an integer >= 1", _int_at_least(1)),
    "unsafe_landing_bound": ("a number in (0, 1)", _in(0.0, 1.0, lo_open=True)),
    "confidence": ("a number in [0.5, 1)", _in(0.5, 1.0)),
    "time_budget_s": ("a number of seconds > 0", _in(0.0, lo_open=True)),
    "pose_error": ("a mapping {height: e, pitch: e} of relative errors, each in [0, 1)", _pose_error),
    "rerun_shards": ("an integer >= 0", _int_at_least(0)),
    "calibration_card": ("a path to a calibration card (uav-el calibrate), or null for none", _card),
    "calibration_min_unsafe": ("an integer >= 1", _int_at_least(1)),
    "radius_m": ("a safety radius R in metres > 0", _in(0.0, lo_open=True)),
    "beta": ("a safety coefficient beta >= 1", _in(1.0, hi=None)),
}
"""Every target the requirement checks read: name -> (what is allowed, its check: the value or None)."""

REQUIRED_TARGETS: tuple[str, ...] = tuple(k for k in TARGETS if k != "calibration_card")
"""The targets a registry must set (``calibration_card`` may be absent: no card chosen)."""


GATE_POLICY = ("size_limited", "waiver_owners", "waiver_max_days", "forbidden_categories", "safe_unknown_accepted")
"""Registry parameters that say what the gate accepts: set in the registry (pinned by hash), never as targets."""


def check_target(name: str, value: Any, *, where: str = "targets") -> Any:
    """``value`` checked and normalised for the target ``name`` (numbers as float, names stripped).

    An unregistered name (a parameter a registry adds for its own checks) keeps any JSON value of the type
    its registry default has; the caller decides which names are known. TargetError names key, value and
    what is allowed.
    """
    spec = TARGETS.get(name)
    if spec is None:
        return value
    allowed, check = spec
    out = check(value)
    if out is None and not (name == "calibration_card" and value is None):
        raise TargetError(f"{where}.{name} = {value!r}: must be {allowed}")
    return out


def validate_targets(targets: Mapping[str, Any], defaults: Mapping[str, Any], *,
                     where: str = "targets") -> dict[str, Any]:
    """The overrides ``targets`` checked against the registry's parameters ``defaults``: a key neither a known
    target nor a registry parameter is refused (naming the known keys); each value is checked (``check_target``);
    a registry parameter without a registered check must keep its default's type."""
    if not isinstance(targets, Mapping):
        raise TargetError(f"{where}: must be a mapping of target names to values, got {type(targets).__name__}")
    known = [k for k in dict.fromkeys([*TARGETS, *defaults]) if k not in GATE_POLICY]
    out: dict[str, Any] = {}
    for name, value in targets.items():
        if name in GATE_POLICY:
            raise TargetError(f"{where}.{name}: the gate's policy is the registry's, not a target a run may override")
        if name not in known:
            raise TargetError(f"{where}: unknown target {name!r}; known: {', '.join(known)}")
        default = defaults.get(name)
        if name not in TARGETS and default is not None and not _same_kind(value, default):
            raise TargetError(f"{where}.{name} = {value!r}: must be of the registry default's type "
                              f"({type(default).__name__}, default {default!r})")
        out[name] = check_target(name, value, where=where)
    return out


def _same_kind(value: Any, default: Any) -> bool:
    if _number(default) is not None:
        return _number(value) is not None
    return type(value) is type(default) or (isinstance(value, list | tuple) and isinstance(default, list | tuple))


def read_targets_file(path: str | Path) -> dict[str, Any]:
    """A JSON object of target overrides (``--uav-el-targets FILE.json``); TargetError naming the file otherwise."""
    path = Path(path)
    try:  # a regular file of at most 1 MiB (a FIFO or a device refused before any read), nested at most 32 deep
        text = userfiles.read_text(path, what="targets file", max_bytes=userfiles.MAX_SETTINGS_BYTES)
        doc = userfiles.parse_bounded(json.loads, text, where=str(path))
    except userfiles.UserFileError as exc:
        raise TargetError(str(exc)) from None
    except json.JSONDecodeError as exc:
        raise TargetError(f"{path}: the targets file is not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise TargetError(f"{path}: the targets file must hold a JSON object of target names to values")
    card = doc.get("calibration_card")
    if isinstance(card, str) and card.strip() and not Path(card).is_absolute():
        doc["calibration_card"] = str((path.resolve().parent / card).resolve())  # relative to the file, not here
    return doc


"""The folder holding the ``el`` and ``assurance`` packages: relative paths in a registry are package data."""


def targets_sha256(parameters: Mapping[str, Any]) -> str:
    """SHA-256 of the effective parameters as canonical JSON: what the results and the report must share."""
    text = json.dumps(dict(parameters), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


_FIELD = re.compile(r"^([a-z_][a-z0-9_]*)((?:\.[a-z_][a-z0-9_]*)*)$")


def _lookup(field: str, params: Mapping[str, Any]) -> Any:
    m = _FIELD.match(field)
    if m is None:
        raise TargetError(f"placeholder {{{field}}}: only a parameter name, optionally .key into a mapping")
    name, keys = m.group(1), [k for k in m.group(2).split(".") if k]
    if name not in params:
        raise TargetError(f"placeholder {{{field}}} names no parameter; known: {', '.join(params)}")
    value: Any = params[name]
    for key in keys:
        if not isinstance(value, Mapping) or key not in value:
            raise TargetError(f"placeholder {{{field}}}: {name} has no key {key!r}")
        value = value[key]
    return value


def format_value(value: Any, spec: str) -> str:
    """One placeholder's text: ``pct`` is the shortest exact percentage (0.975 -> 97.5%), a list is joined
    with commas, a mapping is ``key value`` pairs; any other spec is Python's format mini-language."""
    if isinstance(value, list | tuple):
        return ", ".join(format_value(v, spec) for v in value)
    if isinstance(value, Mapping):
        return ", ".join(f"{k} {format_value(v, spec)}" for k, v in value.items())
    if spec == "pct":
        if _number(value) is None:
            raise TargetError(f"format 'pct' needs a number, got {value!r}")
        return f"{float(value) * 100:.10g}%"
    if value is None:
        return "none"
    return format(value, spec)


def render_text(template: str, params: Mapping[str, Any]) -> str:
    """``template`` with each ``{name[.key][:spec]}`` replaced from ``params`` (``{{``/``}}`` are literal braces).

    Refused (TargetError): a name no parameter has, attribute or index access, a conversion (``!r``), a nested
    placeholder in a spec, a spec that does not fit the value.
    """
    out: list[str] = []
    try:
        parsed = list(string.Formatter().parse(template))
    except ValueError as exc:
        raise TargetError(f"malformed placeholder in {template[:60]!r}... ({exc})") from None
    for literal, field, spec, conversion in parsed:
        out.append(literal)
        if field is None:
            continue
        if conversion is not None or "{" in (spec or ""):
            raise TargetError(f"placeholder {{{field}}}: conversions and nested placeholders are not allowed")
        value = _lookup(field, params)
        try:
            out.append(format_value(value, spec or ""))
        except (TypeError, ValueError) as exc:
            if isinstance(exc, TargetError):
                raise
            raise TargetError(f"placeholder {{{field}:{spec}}}: {exc}") from None
    return "".join(out)


def placeholders(template: str) -> list[str]:
    """The parameter names a template's placeholders read (for checks and documentation)."""
    try:
        return [f.split(".")[0] for _, f, _, _ in string.Formatter().parse(template) if f]
    except ValueError:
        return []
