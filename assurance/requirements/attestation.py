"""The requirement results' signed statement: what ``uav-el verify`` produced, bound to the run it judged.

``sign_results`` writes ``requirements.dsse.json`` beside ``requirements.json``: an in-toto statement whose
subjects are the results JSON and the JUnit XML, and whose predicate pins the run's digest, the campaign's
signed statement, the registry, the effective targets, the waivers file and the system file. Results written
any other way carry no such statement, or one that does not match them, and are not evidence
(``check_results_attestation`` says why, one line each).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from assurance.attest import AttestationError
from assurance.attest.dsse import read_envelope, write_envelope
from assurance.attest.keys import SigningKey
from assurance.attest.statement import make_statement, open_statement, sign_statement, subject_problems
from assurance.campaign.attestation import ATTESTATION as CAMPAIGN
from assurance.campaign.readouts import MAX_RUN_JSON_BYTES, read_manifest
from el.base import userfiles
from el.base.hashing import sha256_file

KIND = "requirements"
ATTESTATION = "requirements.dsse.json"
PINNED = ("run_digest", "campaign_attestation_sha256", "registry_sha256", "parameters_sha256", "waivers_sha256",
          "system_sha256")
"""What the statement pins and the report compares with what it was given."""


def results_pins(run: Path, manifest: Mapping[str, Any], registry: Mapping[str, Any], run_digest: str,
                 waivers: str | Path | None) -> dict[str, Any]:
    """The values a results statement pins (``PINNED``) for ``run``; ``registry``: the registry's ``sha256`` and
    ``parameters_sha256`` (as a results file records them, or from the report's loaded registry)."""
    envelope = Path(run) / CAMPAIGN
    return {"run_digest": run_digest,
            "campaign_attestation_sha256": sha256_file(envelope) if envelope.is_file() else None,
            "registry_sha256": registry.get("sha256"), "parameters_sha256": registry.get("parameters_sha256"),
            "waivers_sha256": sha256_file(waivers) if waivers and Path(waivers).is_file() else None,
            "system_sha256": (manifest.get("system") or {}).get("sha256")}


def sign_session_results(run: str | Path, out: str | Path, key: SigningKey, *, waivers: str | Path | None,
                         extra: Mapping[str, Any] | None = None) -> Path:
    """Sign ``out/requirements.json`` (and ``out/junit.xml``) of a test session on ``run`` with the pins the
    evidence step will compare: the session's run digest, registry and targets, the run's campaign statement and
    system file, the waivers to be applied (``uav-el verify`` calls this after its session)."""
    import json

    run, out = Path(run), Path(out)
    results = out / "requirements.json"

    doc = json.loads(userfiles.read_text(results, what="requirement results", max_bytes=MAX_RUN_JSON_BYTES))
    ctx, reg = doc.get("context") or {}, doc.get("registry") or {}
    manifest = read_manifest(run)  # bounded
    pins = results_pins(run, manifest, reg, ctx.get("run_digest") or "", waivers)
    pins.update(code=ctx.get("code"), waivers=str(waivers) if waivers else None, **dict(extra or {}))
    return sign_results(results, key, pins, junit=out / "junit.xml")


def attestation_path(results: str | Path) -> Path:
    """Where the statement of a results file lies: ``requirements.dsse.json`` in the same folder."""
    return Path(results).with_name(ATTESTATION)


def _subjects(results: Path, junit: Path | None) -> dict[str, str]:
    out = {results.name: sha256_file(results)}
    if junit is not None and junit.is_file():
        out[junit.name] = sha256_file(junit)
    return out


def sign_results(results: str | Path, key: SigningKey, pins: Mapping[str, Any], *,
                 junit: str | Path | None = None) -> Path:
    """Sign a results file (and its JUnit XML) with what it was judged on (``pins``: the keys of ``PINNED`` and
    any others worth stating, e.g. the code identity and the counts of tests collected and run)."""
    results = Path(results)
    stmt = make_statement(_subjects(results, Path(junit) if junit else None), KIND, dict(pins))
    path = attestation_path(results)
    write_envelope(path, sign_statement(stmt, key))
    return path


def check_results_attestation(results: str | Path, trusted: Mapping[str, Any], expected: Mapping[str, Any], *,
                              junit: str | Path | None = None) -> tuple[dict[str, Any], list[str]]:
    """(the signed predicate, problems): the statement must verify against ``trusted`` keys, sign the results
    file as it is now, and pin the same values as ``expected`` for every ``PINNED`` key given there."""
    results = Path(results)
    path = attestation_path(results)
    try:
        stmt, keyid = open_statement(read_envelope(path), trusted, KIND, where=str(path))
    except AttestationError as exc:
        return {}, [f"{exc}: requirement results are evidence only as `uav-el verify` wrote and signed them"]
    problems = [f"{results.parent}: {p}" for p in subject_problems(stmt, _subjects(results, Path(junit) if junit
                                                                                else None))]
    pred = dict(stmt["predicate"], signed_by=keyid)
    for name in PINNED:
        if name in expected and pred.get(name) != expected[name]:
            problems.append(f"{path}: signed with {name} {str(pred.get(name))[:16]}, this report has "
                            f"{str(expected[name])[:16]}")
    return pred, problems
