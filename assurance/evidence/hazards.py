"""The hazard log (``assurance/hazards.yaml``): read, validated against its schema and the requirement registry,
and the trace hazard -> requirement the report and the safety argument show."""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from assurance import requirements as rq
from el.base.errors import DataError
from el.base.hashing import sha256_file
from el.base.safeyaml import load_file

SEVERITIES = ("catastrophic", "hazardous", "major", "minor")


class HazardLogError(DataError):
    """The hazard log is unreadable, breaks its schema or names a requirement the registry lacks."""


@dataclass(frozen=True)
class Hazard:
    """One hazard: what, why, what follows, how bad, and the requirements that mitigate it."""

    id: str
    hazard: str
    cause: str
    effect: str
    severity: str
    source: str
    mitigations: tuple[str, ...]


@dataclass(frozen=True)
class HazardLog:
    """The validated hazard log, in file order, with the file's path and SHA-256."""

    path: Path
    sha256: str
    hazards: tuple[Hazard, ...]

    def of_requirement(self, rid: str) -> list[str]:
        """The ids of the hazards a requirement mitigates."""
        return [h.id for h in self.hazards if rid in h.mitigations]


def default_hazards_path() -> Path:
    """The shipped hazard log, ``assurance/hazards.yaml``."""
    return Path(str(resources.files("assurance").joinpath("hazards.yaml")))


def _schema() -> dict[str, Any]:
    return json.loads(resources.files("assurance").joinpath("data/hazards.schema.json").read_text("utf-8"))


def load_hazards(path: str | Path | None, registry: rq.Registry) -> HazardLog:
    """Read and validate the hazard log against its schema and ``registry`` (every mitigation a known requirement,
    unique hazard ids); HazardLogError naming the file and the first problem."""
    import jsonschema

    path = Path(path) if path else default_hazards_path()
    try:
        doc = load_file(path)
    except (OSError, ValueError) as exc:
        raise HazardLogError(f"{path}: hazard log not readable: {exc}") from None
    errors = sorted(jsonschema.Draft202012Validator(_schema()).iter_errors(doc), key=lambda e: list(map(str, e.path)))
    if errors:
        where = ".".join(map(str, errors[0].absolute_path)) or "(top level)"
        raise HazardLogError(f"{path}: {where}: {errors[0].message}")
    hazards, seen = [], set()
    for entry in doc["hazards"]:
        if entry["id"] in seen:
            raise HazardLogError(f"{path}: hazard {entry['id']} appears twice")
        seen.add(entry["id"])
        unknown = [r for r in entry["mitigations"] if r not in registry]
        if unknown:
            raise HazardLogError(f"{path}: hazard {entry['id']}: mitigation {unknown[0]} is not a requirement of "
                                 f"{registry.path.name}")
        hazards.append(Hazard(entry["id"], entry["hazard"], " ".join(entry["cause"].split()),
                              " ".join(entry["effect"].split()), entry["severity"], entry.get("source", ""),
                              tuple(entry["mitigations"])))
    return HazardLog(path, sha256_file(path), tuple(hazards))


def untraced(log: HazardLog, registry: rq.Registry) -> list[str]:
    """The requirements of ``registry`` that mitigate no hazard of ``log`` (each should mitigate one)."""
    return [rid for rid in registry.ids if not log.of_requirement(rid)]


def hazard_view(log: HazardLog, states: dict[str, str]) -> list[dict[str, Any]]:
    """The hazard log as the report shows it: each hazard with its mitigating requirements and their states."""
    return [{"id": h.id, "hazard": h.hazard, "cause": h.cause, "effect": h.effect, "severity": h.severity,
             "source": h.source,
             "mitigations": [{"id": r, "state": states.get(r, rq.NOT_VERIFIED)} for r in h.mitigations]}
            for h in log.hazards]
