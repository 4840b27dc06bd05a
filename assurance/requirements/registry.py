"""The requirement registry: ``assurance/requirements.yaml`` read and validated (docs/architecture.md 4.6).

``load_registry`` checks unique ids, required fields and known sources, and raises ``RegistryError``
naming the file and the entry.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from el.errors import UavElError

REGISTRY_FORMAT = "uav-el-requirements/1"
KNOWN_SOURCES: tuple[str, ...] = ("SORA", "SSIV21", "ICRA22", "PROJECT")
"""The only sources a requirement may cite (docs/architecture.md section 4.6: never invent a citation)."""

_ID = re.compile(r"^EL-R\d{2,3}$")
_FIELDS: tuple[str, ...] = ("id", "title", "text", "source", "rationale", "verification", "acceptance", "domain")
_PARAMETERS: dict[str, type | tuple[type, ...]] = {
    "deployed_monitor": str,
    "required_perturbations": list,
    "min_images_per_perturbation": int,
    "unsafe_landing_bound": (int, float),
    "confidence": (int, float),
    "time_budget_s": (int, float),
    "pose_error": dict,
    "rerun_shards": int,
}


class RegistryError(UavElError, ValueError):
    """The requirement registry is missing, malformed or inconsistent; the message names file and entry."""


@dataclass(frozen=True)
class Requirement:
    """One safety requirement of the registry."""

    id: str
    title: str
    text: str
    source: tuple[str, ...]
    rationale: str
    verification_method: str
    verification_kind: tuple[str, ...]
    acceptance: str
    domain: str


@dataclass(frozen=True)
class Registry:
    """The validated registry: requirements in file order, the parameters of their acceptance criteria."""

    path: Path
    sha256: str
    sources: dict[str, str]
    parameters: dict[str, Any]
    operating_domain: dict[str, str]
    requirements: dict[str, Requirement]

    def __contains__(self, req_id: object) -> bool:
        return req_id in self.requirements

    def __iter__(self):
        return iter(self.requirements.values())

    def __len__(self) -> int:
        return len(self.requirements)

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(self.requirements)

    def __getitem__(self, req_id: str) -> Requirement:
        return self.requirements[req_id]


def default_registry_path() -> Path:
    """The shipped registry, ``assurance/requirements.yaml``."""
    return Path(str(resources.files("assurance").joinpath("requirements.yaml")))


def _text(where: str, entry: Mapping[str, Any], name: str) -> str:
    value = entry.get(name)
    if not isinstance(value, str) or not value.strip():
        raise RegistryError(f"{where}: field '{name}' must be a non-empty string, got {value!r}")
    return " ".join(value.split())


def _requirement(where: str, entry: Any, sources: Mapping[str, str]) -> Requirement:
    if not isinstance(entry, dict):
        raise RegistryError(f"{where}: a requirement must be a mapping, got {type(entry).__name__}")
    missing = [f for f in _FIELDS if f not in entry]
    if missing:
        raise RegistryError(f"{where}: missing field(s) {', '.join(repr(m) for m in missing)}")
    unknown = sorted(set(entry) - set(_FIELDS))
    if unknown:
        raise RegistryError(f"{where}: unknown field(s) {', '.join(repr(u) for u in unknown)}")
    src = entry["source"]
    if isinstance(src, str):
        src = [src]
    if not isinstance(src, list) or not src or not all(isinstance(s, str) for s in src):
        raise RegistryError(f"{where}: 'source' must be a non-empty list of source keys, got {src!r}")
    bad = [s for s in src if s not in sources]
    if bad:
        raise RegistryError(f"{where}: unknown source(s) {bad}; cite only {', '.join(sources)}")
    ver = entry["verification"]
    if not isinstance(ver, dict) or "method" not in ver:
        raise RegistryError(f"{where}: 'verification' must be a mapping with a 'method'")
    kind = ver.get("kind", [])
    if not isinstance(kind, list) or not all(isinstance(k, str) for k in kind):
        raise RegistryError(f"{where}: 'verification.kind' must be a list of strings, got {kind!r}")
    return Requirement(
        id=entry["id"], title=_text(where, entry, "title"), text=_text(where, entry, "text"),
        source=tuple(src), rationale=_text(where, entry, "rationale"),
        verification_method=_text(where, ver, "method"), verification_kind=tuple(kind),
        acceptance=_text(where, entry, "acceptance"), domain=_text(where, entry, "domain"),
    )


def _parameters(path: Path, params: Any) -> dict[str, Any]:
    """The registry's ``parameters``, checked for presence, type and range."""
    if not isinstance(params, dict):
        raise RegistryError(f"{path}: 'parameters' must be a mapping")
    for name, typ in _PARAMETERS.items():
        if name not in params:
            raise RegistryError(f"{path}: parameters: missing {name!r}")
        if isinstance(params[name], bool) or not isinstance(params[name], typ):
            raise RegistryError(f"{path}: parameters.{name} has the wrong type ({params[name]!r})")
    if not 0 < params["unsafe_landing_bound"] < 1 or not 0 < params["confidence"] < 1:
        raise RegistryError(f"{path}: parameters.unsafe_landing_bound and confidence must lie in (0, 1)")
    if params["min_images_per_perturbation"] < 1 or params["rerun_shards"] < 0 or params["time_budget_s"] <= 0:
        raise RegistryError(f"{path}: parameters: min_images_per_perturbation >= 1, rerun_shards >= 0, "
                            "time_budget_s > 0")
    return params


def load_registry(path: str | Path | None = None) -> Registry:
    """Read and validate a requirement registry (default: the shipped one).

    Raises RegistryError for a missing or unparsable file, a wrong format tag, a requirement without
    one of the required fields, a malformed or duplicate id, an unknown source, or a missing parameter.
    """
    path = Path(path) if path is not None else default_registry_path()
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RegistryError(f"{path}: cannot read the requirement registry ({exc.strerror or exc})") from None
    try:
        doc = yaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise RegistryError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(doc, dict):
        raise RegistryError(f"{path}: the registry must be a YAML mapping")
    if doc.get("format") != REGISTRY_FORMAT:
        raise RegistryError(f"{path}: format must be {REGISTRY_FORMAT!r}, got {doc.get('format')!r}")
    sources = doc.get("sources")
    if not isinstance(sources, dict) or not sources:
        raise RegistryError(f"{path}: 'sources' must be a non-empty mapping")
    invented = sorted(set(sources) - set(KNOWN_SOURCES))
    if invented:
        raise RegistryError(f"{path}: sources {invented} are not allowed; cite only {', '.join(KNOWN_SOURCES)}")
    params = _parameters(path, doc.get("parameters"))
    domain = doc.get("operating_domain")
    if not isinstance(domain, dict) or not all(isinstance(v, str) for v in domain.values()):
        raise RegistryError(f"{path}: 'operating_domain' must be a mapping of strings")
    entries = doc.get("requirements")
    if not isinstance(entries, list) or not entries:
        raise RegistryError(f"{path}: 'requirements' must be a non-empty list")
    reqs: dict[str, Requirement] = {}
    for i, entry in enumerate(entries):
        rid = entry.get("id") if isinstance(entry, dict) else None
        where = f"{path}: requirements[{i}]" + (f" ({rid})" if isinstance(rid, str) else "")
        if not isinstance(rid, str) or not _ID.match(rid):
            raise RegistryError(f"{where}: 'id' must look like 'EL-R01', got {rid!r}")
        if rid in reqs:
            raise RegistryError(f"{where}: duplicate id {rid!r}")
        reqs[rid] = _requirement(where, entry, sources)
    return Registry(path=path, sha256=hashlib.sha256(raw).hexdigest(), sources=dict(sources),
                    parameters=dict(params), operating_domain={k: " ".join(v.split()) for k, v in domain.items()},
                    requirements=reqs)
