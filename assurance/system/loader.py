"""Read a system file (``uav-el.toml``): TOML by the standard library, validated against the packaged JSON Schema.

Every error is one line naming the file, the key, the value and what is allowed (``SystemFileError``, a
``ValueError``: exit 2 at the command line). Without a file, the embedded default (``default.toml`` in this
package: the shipped system) is used, so a command given no system file behaves as it always did.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import re
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from assurance.system import build
from el.base import userfiles
from el.base.errors import UavElError

SYSTEM_FILE = "uav-el.toml"
FORMAT = "uav-el-system/1"
REPLACED_WHOLE = ("model", "labels")  # a user's section replaces the default's (its keys exclude each other)
MAX_BYTES = 1_000_000  # a system file is a page of settings, not data
MAX_DEPTH = 8  # tables, arrays and dotted keys nest at most this deep (the schema's deepest value nests 4)


class SystemFileError(UavElError, ValueError):
    """A system file that cannot be used: one line naming the file, the key, the value and what is allowed."""


@cache
def schema() -> dict[str, Any]:
    """The system file's JSON Schema (``assurance/system/schema.json``)."""
    text = resources.files("assurance.system").joinpath("schema.json").read_text(encoding="utf-8")
    return json.loads(text)


@dataclass(frozen=True)
class SystemFile:
    """A validated system file: where it is, its SHA-256, what it sets, and the settings in effect.

    ``document`` is what the file itself sets; ``settings`` is that merged over the embedded default
    (sections ``model`` and ``labels`` are replaced whole, the others key by key). Relative paths are
    relative to ``base``, the file's folder.
    """

    path: Path | None
    sha256: str
    document: dict[str, Any]
    settings: dict[str, Any]
    base: Path
    default: bool = False
    _cache: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def label(self) -> str:
        """How messages name the file: its path, or "the embedded default system"."""
        return "the embedded default system" if self.path is None else str(self.path)

    @property
    def name(self) -> str:
        return str(self.get("system.name", "unnamed system"))

    def get(self, key: str, default: Any = None) -> Any:
        """A setting in effect by dotted key (``"camera.height_m"``), or ``default``."""
        return _lookup(self.settings, key, default)

    def sets(self, key: str) -> bool:
        """Whether the file itself (not the default) sets ``key``."""
        return _lookup(self.document, key, _UNSET) is not _UNSET

    def path_of(self, key: str) -> Path | None:
        """The setting ``key`` as a path, relative ones resolved against the file's folder, normalised (``sys/../raw``
        is ``raw``: one spelling, as the files found under it are spelled); None when unset."""
        value = self.get(key)
        if value is None:
            return None
        p = Path(str(value)).expanduser()
        return Path(os.path.normpath(p if p.is_absolute() else (self.base / p)))

    def error(self, key: str, problem: str) -> SystemFileError:
        """The one-line error about ``key`` of this file."""
        return SystemFileError(f"{self.label}: {key}: {problem}")

    def values(self) -> list[tuple[str, str]]:
        """Every value the file sets, as (dotted key, JSON text), in file order: what the report shows."""
        return [(k, json.dumps(v, sort_keys=True, ensure_ascii=False)) for k, v in _flatten(self.document)]

    # -- what the file declares, typed (assurance.system.build reads each section; nothing outside the system package
    # reads a section itself) ------------------------------------------------------------------------------------
    def labels(self) -> Any:
        """The label set (``[labels]``; ``el.classes.labels.LabelSet``)."""
        return build.label_set(self)

    def core(self, **overrides: Any) -> Any:
        """The core model's configuration: camera, nominal pose, safety (``el.geometry.config.CoreConfig``)."""
        return build.core_config(self, **overrides)

    def odd(self) -> Any:
        """The declared operating domain (``[odd]``; ``el.geometry.odd.OperatingDomain``)."""
        return build.odd(self)

    def poses(self) -> str:
        """The pose policy (``camera.poses``)."""
        return build.poses_policy(self)

    def camera_named(self) -> bool:
        """Whether the camera's name is declared (``assurance.system.build.camera_named``)."""
        return build.camera_named(self)

    def image_size(self) -> tuple[int, int]:
        """The camera's image size (width, height)."""
        return build.image_size(self)

    def data(self, split: str, given: str | Path | None = None) -> Any:
        """The data of ``split``: ``given``, else ``[data] <split>`` (``assurance.system.build.data_root``)."""
        return build.data_root(self, split, given)

    def declares_data(self, split: str) -> bool:
        """Whether ``[data]`` names a ``split``."""
        return self.get(f"data.{split}") is not None

    def targets(self) -> dict[str, Any]:
        """The requirement targets the file sets (``[targets]``)."""
        return build.targets(self)

    def target_origins(self) -> dict[str, str]:
        """Where the file sets each requirement parameter of its own."""
        return build.target_origins(self)

    def waivers(self, given: str | None = None) -> str | None:
        """The waivers file: ``given``, else the file's, else the shipped one."""
        return build.waivers(self, given)

    def report_settings(self) -> dict[str, Any]:
        """``[report]``: title, organisation, templates."""
        return build.report_settings(self)

    def in_service(self) -> dict[str, Any]:
        """``[in_service]``: the safety performance indicators."""
        return build.in_service(self)

    @property
    def declares_perturbations(self) -> bool:
        """Whether the file itself declares ``[odd] perturbations`` (not the default's)."""
        return self.sets("odd.perturbations")

    @property
    def names_monitor(self) -> bool:
        """Whether the file itself names its monitor (``[monitor] spec``)."""
        return self.sets("monitor.spec")

    @property
    def labels_preset(self) -> str | None:
        """The packaged label set the file names (``[labels] preset``), None for a file of its own or none."""
        value = self.get("labels.preset")
        return None if value is None else str(value)

    @property
    def labels_file(self) -> Path | None:
        """The label set file the file names (``[labels] file``), resolved."""
        return self.path_of("labels.file")

    def provenance(self, key: str) -> Any:
        """A ``[model.provenance]`` entry (``trained_by``, ``training_data``, ...), None when unset."""
        return self.get(f"model.provenance.{key}")

    def data_note(self, key: str) -> Any:
        """What ``[data]`` says of the data besides its splits (``provenance``, ``licence``), None when unset."""
        return self.get(f"data.{key}")

    @property
    def required_perturbations(self) -> Any:
        """``[targets] required_perturbations`` as set (None: unset)."""
        return self.get("targets.required_perturbations")

    @property
    def time_budget_s(self) -> Any:
        """``[targets] time_budget_s`` in effect (None: no deadline)."""
        return self.get("targets.time_budget_s")

    def report_text(self, key: str, default: str) -> str:
        """A text of ``[report]`` (``title``, ``organisation``), else ``default``."""
        return str(self.get(f"report.{key}", default))

    def record(self) -> dict[str, Any]:
        """The JSON record of this system file (manifests, requirement results, the report)."""
        return {"path": None if self.path is None else str(self.path.resolve()), "sha256": self.sha256,
                "name": self.name, "default": self.default, "document": self.document}


_UNSET = object()


def _lookup(doc: Mapping[str, Any], key: str, default: Any) -> Any:
    """``doc``'s value at a dotted key, or ``default`` when a part is missing."""
    value: Any = doc
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return default
        value = value[part]
    return value


def _flatten(doc: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    for key, value in doc.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            yield from _flatten(value, dotted + ".")
        else:
            yield dotted, value


def parse_system(text: str, *, label: str) -> dict[str, Any]:
    """The validated document of a system file's text; ``SystemFileError`` naming ``label`` and the key.

    Its nesting is measured before ``tomllib`` reads it (``el.base.userfiles.toml_nesting``: ``tomllib`` recurses on
    brackets, 60 000 deep is a RecursionError, and takes quadratic time on a long dotted key)."""
    depth = userfiles.toml_nesting(text, limit=MAX_DEPTH)
    if depth > MAX_DEPTH:
        raise SystemFileError(f"{label}: nested more than {MAX_DEPTH} levels deep (brackets, braces or dotted key "
                              "parts); a system file is a page of settings")
    try:
        doc = userfiles.parse_bounded(tomllib.loads, text, where=label, max_depth=MAX_DEPTH)
    except tomllib.TOMLDecodeError as exc:
        raise SystemFileError(f"{label}: not valid TOML: {exc}{toml_hint(text, str(exc))}") from None
    except userfiles.UserFileError as exc:
        raise SystemFileError(str(exc)) from None
    validate(doc, label=label)
    return doc


_AT_LINE = re.compile(r"\(at line (\d+), column \d+\)")
_STRING = re.compile(r'"(?:\\.|[^"\\])*"|\'[^\']*\'')  # a basic or literal string on one line
_HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(?:#.*)?$")


def toml_hint(text: str, message: str) -> str:
    """A hint for ``tomllib``'s error ``message`` on ``text``: the key set twice ("Cannot overwrite a value" names
    none), or a line that opens an inline table it does not close ("Invalid initial character for a key part" says
    nothing of why: TOML's ``{ ... }`` must fit on one line). Empty for any other error."""
    at = _AT_LINE.search(message)
    lines = text.splitlines()
    if at is None or not 1 <= int(at.group(1)) <= len(lines):
        return ""
    n = int(at.group(1))
    code = _STRING.sub('""', lines[n - 1]).split("#", 1)[0]
    key = code.split("=", 1)[0].strip() if "=" in code else ""
    header = next((m.group(1) for line in reversed(lines[:n - 1]) if (m := _HEADER.match(line))), "")
    if message.startswith("Cannot overwrite a value"):
        opened = _HEADER.match(code)  # a [table] header declared twice
        dotted = ".".join(part for part in (header, key) if part) if key else opened.group(1) if opened else ""
        if dotted:
            return f": {dotted} is set twice (once is allowed)"
    if code.count("{") <= code.count("}"):
        return ""
    table = ".".join(part for part in (header, key) if part) or "section.sub"
    return f": an inline table {{ ... }} must fit on one line; use a [{table}] table instead"


def validate(doc: Mapping[str, Any], *, label: str) -> None:
    """Check a document against the schema; the first problem (in key order) as one line. A number that is NaN or
    infinite is refused wherever it stands (NaN passes every ``minimum``/``maximum`` of a schema: it compares
    false), so no setting reaches a command as NaN."""
    import jsonschema

    try:  # a document recorded in a run's manifest reaches here without parse_system's bound
        userfiles.check_depth(dict(doc), where=label, max_depth=MAX_DEPTH)
    except userfiles.UserFileError as exc:
        raise SystemFileError(str(exc)) from None
    bad = userfiles.non_finite(dict(doc))
    if bad is not None:
        raise SystemFileError(f"{label}: {bad[0]} = {bad[1]}: must be a finite number")
    hidden = userfiles.hidden_character(dict(doc))
    if hidden is not None:
        raise SystemFileError(f"{label}: {hidden[0]}: holds the invisible character {hidden[1]} (a control or "
                              "format character, e.g. a right-to-left override, makes a text display other than "
                              "it reads): remove it")

    validator = jsonschema.Draft202012Validator(schema())
    errors = sorted(validator.iter_errors(doc), key=lambda e: (list(map(str, e.absolute_path)), e.validator))
    if errors:
        raise SystemFileError(f"{label}: {describe_error(errors[0])}")


def describe_error(err: Any) -> str:
    """One line for a jsonschema error: the dotted key, the value, what is allowed."""
    key = ".".join(str(p) for p in err.absolute_path) or "(top level)"
    value = err.instance
    shown = json.dumps(value) if not isinstance(value, dict) else "a table"
    kind, arg = err.validator, err.validator_value
    if kind == "additionalProperties":
        allowed = sorted((err.schema.get("properties") or {}).keys())
        extra = sorted(set(value) - set(allowed)) if isinstance(value, dict) else []
        where = f"{key}." if err.absolute_path else ""
        if not allowed:  # a free-form table whose values have a type
            return f"{key}: {describe_type(err.schema.get('additionalProperties'))}"
        return f"unknown key {where}{extra[0] if extra else '?'}; allowed here: {', '.join(allowed)}"
    if kind == "enum":
        return f"{key} = {shown}: allowed: {', '.join(json.dumps(a) for a in arg)}"
    if kind == "const":
        return f"{key} = {shown}: must be {json.dumps(arg)}"
    if kind == "type":
        return f"{key} = {shown}: must be {_TYPES.get(str(arg), arg)}"
    bounds = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">", "exclusiveMaximum": "<"}
    if kind in bounds:
        return f"{key} = {shown}: must be {bounds[kind]} {arg}"
    if kind == "pattern":
        return f"{key} = {shown}: must be 64 lowercase hex digits (a SHA-256)" if "64" in str(arg) else \
            f"{key} = {shown}: must match {arg}"
    if kind in ("minItems", "maxItems"):
        return f"{key} = {shown}: needs {'at least' if kind == 'minItems' else 'at most'} {arg} item(s)"
    if kind in ("minLength", "maxLength"):
        return f"{key} = {shown}: needs {'at least' if kind == 'minLength' else 'at most'} {arg} character(s)"
    if kind == "required":
        return f"{key}: missing key(s) {', '.join(arg)}"
    if kind == "uniqueItems":
        return f"{key} = {shown}: items must be unique"
    return f"{key} = {shown}: {err.message}"


_TYPES = {"number": "a number", "integer": "an integer", "string": "a string", "object": "a table",
          "array": "a list", "boolean": "true or false"}


def describe_type(sub: Any) -> str:
    kind = (sub or {}).get("type", "?") if isinstance(sub, Mapping) else "?"
    return f"every value must be {_TYPES.get(str(kind), kind)}"


@cache
def _default_text() -> str:
    return resources.files("assurance.system").joinpath("default.toml").read_text(encoding="utf-8")


def merge(default: Mapping[str, Any], doc: Mapping[str, Any]) -> dict[str, Any]:
    """The settings in effect: ``doc`` over ``default`` (``model`` and ``labels`` replaced whole)."""
    out = copy.deepcopy(dict(default))
    for section, value in doc.items():
        if isinstance(value, Mapping) and section not in REPLACED_WHOLE and isinstance(out.get(section), Mapping):
            out[section] = {**out[section], **copy.deepcopy(dict(value))}
        else:
            out[section] = copy.deepcopy(value)
    return out


def default_system() -> SystemFile:
    """The embedded default: the shipped system (``assurance/system/default.toml``)."""
    text = _default_text()
    doc = parse_system(text, label="the embedded default system")
    base = Path(str(resources.files("assurance.system")))
    return SystemFile(None, hashlib.sha256(text.encode("utf-8")).hexdigest(), doc, merge({}, doc), base,
                      default=True)


def system_from_record(record: Mapping[str, Any]) -> SystemFile:
    """The system file a run recorded (``SystemFile.record()`` in its manifest), validated again: what the
    requirement checks of that run read (targets, R, the deployed monitor), whatever the file says today."""
    if record.get("default"):
        return default_system()
    path = Path(str(record.get("path") or "recorded-system.toml"))
    label = f"{path} (as recorded in the run)"
    document = record.get("document") or {}
    if not isinstance(document, Mapping):
        raise SystemFileError(f"{label}: the recorded document is not a table of settings")
    doc = dict(document)
    validate(doc, label=label)
    default = parse_system(_default_text(), label="the embedded default system")
    return SystemFile(path, str(record.get("sha256") or ""), doc, merge(default, doc), path.parent)


def read_system(path: str | Path) -> SystemFile:
    """Read and validate a system file against the schema (``SystemFileError`` naming file, key, value, allowed);
    the checks beyond the schema are ``assurance.system.checks`` (``assurance.system.load_system`` runs both)."""
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise SystemFileError(f"{path}: no such system file")
    try:  # a regular file of at most MAX_BYTES, refused before any read that could block
        raw = userfiles.read_bytes(path, what="system file", max_bytes=MAX_BYTES)
    except userfiles.UserFileError as exc:
        raise SystemFileError(str(exc)) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SystemFileError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    doc = parse_system(text, label=str(path))
    default = parse_system(_default_text(), label="the embedded default system")
    return SystemFile(path, hashlib.sha256(raw).hexdigest(), doc, merge(default, doc), path.resolve().parent)
