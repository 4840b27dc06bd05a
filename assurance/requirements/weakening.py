"""Is a requirement registry (with its targets) at least as strong as the system's? Each way it is weaker, named.

The system's registry is the packaged one with the system file's ``[targets]`` applied: both are pinned (the
code identity covers the packaged registry, the campaign's signed statement the system file). A registry or
targets given on the command line are not pinned, so they may only tighten it: a lower unsafe-landing bound, a
higher confidence, more images or perturbations, fewer undecidable requirements, more requirements. Anything
that loosens it (or that cannot be ranked, like another deployed monitor) is a weakening, one line each.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from assurance.paths import card_path
from el.base.hashing import sha256_file

LOWER, HIGHER, SUPERSET, SUBSET, EQUAL, EACH_HIGHER = "lower", "higher", "superset", "subset", "equal", "each higher"

STRONGER: dict[str, str] = {
    "unsafe_landing_bound": LOWER,
    "confidence": HIGHER,
    "min_images_per_perturbation": HIGHER,
    "required_perturbations": SUPERSET,
    "time_budget_s": LOWER,
    "pose_error": EACH_HIGHER,
    "rerun_shards": HIGHER,
    "radius_m": HIGHER,
    "beta": HIGHER,
    "calibration_min_unsafe": HIGHER,
    "size_limited": SUBSET,
    "waiver_owners": SUBSET,
    "waiver_max_days": LOWER,
    "forbidden_categories": SUPERSET,
    "safe_unknown_accepted": SUBSET,
    "deployed_monitor": EQUAL,
    "calibration_card": EQUAL,
}
"""Which way each known parameter is stronger; a parameter not listed must keep the system's value."""

_WORD = {LOWER: "higher (looser)", HIGHER: "lower (looser)", SUPERSET: "missing", SUBSET: "added",
         EACH_HIGHER: "smaller (looser)", EQUAL: "different"}


def _card_identity(value: Any) -> Any:
    """A calibration card compared by content (its SHA-256), wherever its path points; None for none."""
    path = card_path(value)
    if path is None:
        return None
    return sha256_file(path) if path.is_file() else f"missing file {path}"


def _weaker(kind: str, ref: Any, given: Any) -> Any:
    """What makes ``given`` weaker than ``ref`` under ``kind`` (falsy when it is not)."""
    checks: dict[str, Callable[[], Any]] = {
        LOWER: lambda: float(given) > float(ref),
        HIGHER: lambda: float(given) < float(ref),
        SUPERSET: lambda: sorted(set(ref) - set(given)),
        SUBSET: lambda: sorted(set(given) - set(ref)),
        EACH_HIGHER: lambda: sorted(k for k in ref if float(given.get(k, 0.0)) < float(ref[k])),
        EQUAL: lambda: given != ref,
    }
    try:
        return checks[kind]()
    except (TypeError, ValueError, AttributeError):
        return True  # not comparable: not shown to be as strong


def _show(value: Any) -> str:
    return json.dumps(value, sort_keys=True, default=str) if not isinstance(value, str) else repr(value)


def parameter_weakenings(reference: Mapping[str, Any], given: Mapping[str, Any]) -> list[str]:
    """One line per parameter of ``given`` weaker than in ``reference`` (or missing, or unrankable and changed)."""
    out = []
    for name, ref in reference.items():
        if name not in given:
            out.append(f"parameter {name} is missing (the system's: {_show(ref)})")
            continue
        value, kind = given[name], STRONGER.get(name, EQUAL)
        if name == "calibration_card":
            ref, value = _card_identity(ref), _card_identity(value)
        what = _weaker(kind, ref, value)
        if not what:
            continue
        if isinstance(what, list):
            out.append(f"parameter {name}: {', '.join(map(str, what))} {_WORD[kind]} (the system's: {_show(ref)}, "
                       f"given: {_show(value)})")
        elif name == "calibration_card":
            out.append(f"parameter calibration_card: another card than the system's ({given[name]!r})")
        else:
            out.append(f"parameter {name} = {_show(value)} is {_WORD[kind]} than the system's {_show(ref)}")
    return out


def registry_weakenings(reference: Any, given: Any) -> list[str]:
    """How the registry ``given`` (an ``assurance.requirements.Registry`` with its targets) is weaker than
    ``reference``: requirements it lacks, then parameters (``parameter_weakenings``); empty when it is at least
    as strong (an identical registry, or a stronger one)."""
    if given.sha256 == reference.sha256 and given.parameters_sha256 == reference.parameters_sha256:
        return []
    where = _where(given)
    missing = [rid for rid in reference.ids if rid not in given]
    out = [f"{where}: requirement {rid} is missing (the system's registry has it)" for rid in missing]
    out += [f"{where}: {line}" for line in parameter_weakenings(reference.parameters, given.parameters)]
    return out


def _where(registry: Any) -> str:
    source = getattr(registry, "targets_source", None)
    path = Path(getattr(registry, "path", "") or "registry")
    return f"{path}" + (f" with targets {source}" if source and getattr(registry, "targets", None) else "")
