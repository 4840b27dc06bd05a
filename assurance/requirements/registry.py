"""The requirement registry: ``assurance/requirements.yaml`` read and validated (docs/architecture.md 4.6).

``load_registry`` checks the registry's structure against its JSON Schema (``assurance/data/registry.schema.json``,
with jsonschema: fields, id pattern, types), then what a schema cannot say: unique ids, known sources, the
parameters' values (``targets``); it renders the requirement texts from the parameters, and raises
``RegistryError`` naming the file and the entry;
``load_registry(targets=...)`` / ``Registry.with_targets`` apply a user's target overrides.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from assurance.requirements.system_facts import TEMPLATE_FACTS, check_facts, shipped_facts
from assurance.requirements.targets import (
    REQUIRED_TARGETS,
    TargetError,
    check_target,
    render_text,
    targets_sha256,
    validate_targets,
)
from el.base import safeyaml, userfiles
from el.base.errors import UavElError

REGISTRY_FORMAT = "uav-el-requirements/1"
KNOWN_SOURCES: tuple[str, ...] = ("SORA", "SSIV21", "ICRA22", "PROJECT")
"""The only sources a requirement may cite (docs/architecture.md section 4.6: never invent a citation)."""



class RegistryError(UavElError, ValueError):
    """The requirement registry is missing, malformed or inconsistent; the message names file and entry."""


@dataclass(frozen=True)
class Requirement:
    """One safety requirement of the registry (its texts rendered from the registry's parameters)."""

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
    """The validated registry: requirements in file order, the parameters of their acceptance criteria.

    ``parameters`` are the effective targets: the file's ``defaults`` with the user's overrides ``targets``
    (from ``targets_source``) applied; requirement texts and the operating domain are rendered from them.
    """

    path: Path
    sha256: str
    sources: dict[str, str]
    parameters: dict[str, Any]
    operating_domain: dict[str, str]
    requirements: dict[str, Requirement]
    defaults: dict[str, Any] = field(default_factory=dict)
    targets: dict[str, Any] = field(default_factory=dict)
    targets_source: str | None = None
    templates: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)
    facts: Mapping[str, str] = field(default_factory=dict, repr=False, compare=False)

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

    @property
    def parameters_sha256(self) -> str:
        """SHA-256 of the effective parameters (canonical JSON): binds requirement results and report to the targets."""
        return targets_sha256(self.parameters)

    def with_targets(self, targets: Mapping[str, Any] | None, *, source: str | None = None) -> Registry:
        """This registry with ``targets`` overriding its parameters (on top of any applied before) and its texts
        rendered again. TargetError for an unknown key (naming the known ones) or a value out of range."""
        if not targets:
            return self
        given = validate_targets(targets, self.defaults, where=source or "targets")
        merged = {**self.targets, **given}
        return _build(self.path, self.sha256, self.sources, self.defaults, self.templates, merged,
                      source or self.targets_source, self.facts)

    def for_system(self, facts: Mapping[str, str] | None) -> Registry:
        """This registry with its texts rendered for the system ``facts`` describe
        (``assurance.requirements.system_facts.facts_of``): its camera, pose, scenes and forbidden classes."""
        if not facts:
            return self
        return _build(self.path, self.sha256, self.sources, self.defaults, self.templates, self.targets,
                      self.targets_source, facts)


def default_registry_path() -> Path:
    """The shipped registry, ``assurance/requirements.yaml``."""
    return Path(str(resources.files("assurance").joinpath("requirements.yaml")))


def _text(where: str, entry: Mapping[str, Any], name: str, params: Mapping[str, Any]) -> str:
    value = entry.get(name)
    if not isinstance(value, str) or not value.strip():
        raise RegistryError(f"{where}: field '{name}' must be a non-empty string, got {value!r}")
    try:
        return " ".join(render_text(value, params).split())
    except TargetError as exc:
        raise RegistryError(f"{where}: field '{name}': {exc}") from None


def _requirement(where: str, entry: dict[str, Any], sources: Mapping[str, str],
                 params: Mapping[str, Any]) -> Requirement:
    """One requirement (its structure already checked by the schema): sources known, texts rendered."""
    src = [entry["source"]] if isinstance(entry["source"], str) else list(entry["source"])
    bad = [s for s in src if s not in sources]
    if bad:
        raise RegistryError(f"{where}: unknown source(s) {bad}; cite only {', '.join(sources)}")
    ver = entry["verification"]
    return Requirement(
        id=entry["id"], title=_text(where, entry, "title", params), text=_text(where, entry, "text", params),
        source=tuple(src), rationale=_text(where, entry, "rationale", params),
        verification_method=_text(where, ver, "method", params), verification_kind=tuple(ver.get("kind", [])),
        acceptance=_text(where, entry, "acceptance", params), domain=_text(where, entry, "domain", params),
    )


@cache
def _schema() -> Any:
    import json

    from jsonschema import Draft202012Validator

    text = resources.files("assurance").joinpath("data", "registry.schema.json").read_text(encoding="utf-8")
    return Draft202012Validator(json.loads(text))


def _schema_problem(path: Path, doc: Any) -> str | None:
    """The registry's first structural problem by its JSON Schema, as one line naming the entry; None if none."""
    from jsonschema.exceptions import best_match

    error = best_match(_schema().iter_errors(doc), key=lambda e: (len(e.absolute_path), e.validator != "required"))
    if error is None:
        return None
    loc = list(error.absolute_path)
    where = str(path)
    if len(loc) >= 2 and loc[0] == "requirements" and isinstance(loc[1], int):
        entry = doc["requirements"][loc[1]]
        rid = entry.get("id") if isinstance(entry, dict) else None
        where += f": requirements[{loc[1]}]" + (f" ({rid})" if isinstance(rid, str) else "")
        loc = loc[2:]
    elif loc:
        where += f": {loc[0]}"
        loc = loc[1:]
    field = ".".join(str(x) for x in loc)
    if error.validator == "required":
        missing = [r for r in error.validator_value if r not in error.instance]
        return f"{where}: missing field(s) {', '.join(repr(m) for m in missing)}"
    if error.validator == "additionalProperties":
        unknown = sorted(set(error.instance) - set(error.schema.get("properties", {})))
        return f"{where}: unknown field(s) {', '.join(repr(u) for u in unknown)}"
    if field == "id":
        return f"{where}: 'id' must look like 'EL-R01', got {error.instance!r}"
    if error.validator == "const" and not field:
        return f"{where} must be {error.validator_value!r}, got {error.instance!r}"
    return f"{where}: " + (f"field '{field}': " if field else "") + error.message


def _parameters(path: Path, params: Any) -> dict[str, Any]:
    """The registry's ``parameters``, checked for presence, type and range (``targets.TARGETS``)."""
    if not isinstance(params, dict):
        raise RegistryError(f"{path}: 'parameters' must be a mapping")
    missing = [name for name in REQUIRED_TARGETS if name not in params]
    if missing:
        raise RegistryError(f"{path}: parameters: missing {', '.join(repr(m) for m in missing)}")
    out = dict(params)
    out.setdefault("calibration_card", None)
    try:
        for name, value in out.items():
            out[name] = check_target(name, value, where=f"{path}: parameters")
    except TargetError as exc:
        raise RegistryError(str(exc)) from None
    return out


def _build(path: Path, sha: str, sources: dict[str, str], defaults: dict[str, Any], templates: Mapping[str, Any],
           targets: dict[str, Any], source: str | None, facts: Mapping[str, str] | None = None) -> Registry:
    """The registry with ``targets`` (already validated) over ``defaults``, its texts rendered from the result
    and the system's ``facts`` (the shipped system's when None)."""
    params = {**defaults, **targets}
    facts = check_facts(dict(facts) if facts else shipped_facts())
    # a fact is a value, substituted once into the registry's texts: its own braces are never read as placeholders
    # (a camera "Cam {A}", a class "{confidence:pct} x"); only the toolkit's wording of the pose is a template
    text_params = {**params, **{k: _text(f"{path}: system facts", facts, k, params) if k in TEMPLATE_FACTS
                                else " ".join(facts[k].split()) for k in facts}}
    reqs: dict[str, Requirement] = {}
    for i, entry in enumerate(templates["requirements"]):
        rid = entry["id"]  # the schema checked its form
        where = f"{path}: requirements[{i}] ({rid})"
        if rid in reqs:
            raise RegistryError(f"{where}: duplicate id {rid!r}")
        reqs[rid] = _requirement(where, entry, sources, text_params)
    domain = {k: _text(f"{path}: operating_domain", templates["operating_domain"], k, text_params)
              for k in templates["operating_domain"]}
    return Registry(path=path, sha256=sha, sources=dict(sources), parameters=params, operating_domain=domain,
                    requirements=reqs, defaults=dict(defaults), targets=dict(targets), targets_source=source,
                    templates=templates, facts=facts)


def load_registry(path: str | Path | None = None, *, targets: Mapping[str, Any] | None = None,
                  targets_source: str | None = None) -> Registry:
    """Read and validate a requirement registry (default: the shipped one), with ``targets`` overriding its
    parameters (``Registry.with_targets``) and every text rendered from the result.

    Raises RegistryError for a missing or unparsable file, a wrong format tag, a requirement without
    one of the required fields, a malformed or duplicate id, an unknown source, a missing or out-of-range
    parameter, or a text whose placeholder names no parameter; TargetError for a bad override.
    """
    path = Path(path) if path is not None else default_registry_path()
    try:  # a regular file of at most 1 MiB: a FIFO or a device is refused before any read
        raw = userfiles.read_bytes(path, what="requirement registry", max_bytes=userfiles.MAX_SETTINGS_BYTES)
    except userfiles.UserFileError as exc:
        raise RegistryError(str(exc)) from None
    try:
        doc = safeyaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise RegistryError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(doc, dict):
        raise RegistryError(f"{path}: the registry must be a YAML mapping")
    problem = _schema_problem(path, doc)
    if problem:
        raise RegistryError(problem)
    sources = doc["sources"]
    invented = sorted(set(sources) - set(KNOWN_SOURCES))
    if invented:
        raise RegistryError(f"{path}: sources {invented} are not allowed; cite only {', '.join(KNOWN_SOURCES)}")
    params = _parameters(path, doc["parameters"])
    domain = doc["operating_domain"]
    entries = doc["requirements"]
    templates = {"requirements": entries, "operating_domain": domain}
    reg = _build(path, hashlib.sha256(raw).hexdigest(), dict(sources), params, templates, {}, None)
    return reg.with_targets(targets, source=targets_source)
