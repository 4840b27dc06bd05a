"""in-toto Statement v1: subjects (name -> SHA-256) and a typed predicate, signed in a DSSE envelope.

``sign_statement`` makes the envelope; ``open_statement`` verifies it against trusted keys and returns the
statement; ``subject_problems`` compares a statement's subjects with the files as they are now, one line
per file missing, extra or altered.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from assurance.attest.dsse import AttestationError, sign_envelope, verify_envelope
from assurance.attest.keys import SigningKey
from el.base import userfiles

STATEMENT_TYPE = "https://in-toto.io/Statement/v1"
PREDICATE_BASE = "urn:uav-el-assurance:attestation:"
"""Predicate types are ``PREDICATE_BASE + <name>:v1`` (``campaign``, ``requirements``): a URN, since the
project publishes no schema site."""


def predicate_type(name: str) -> str:
    """The predicate type URI of one of the project's statements."""
    return f"{PREDICATE_BASE}{name}:v1"


def make_statement(subjects: Mapping[str, str], kind: str, predicate: Mapping[str, Any]) -> dict[str, Any]:
    """A statement over ``subjects`` (name -> SHA-256 hex, kept in sorted order) with a ``kind`` predicate."""
    return {"_type": STATEMENT_TYPE,
            "subject": [{"name": n, "digest": {"sha256": d}} for n, d in sorted(subjects.items())],
            "predicateType": predicate_type(kind), "predicate": dict(predicate)}


def sign_statement(statement: Mapping[str, Any], key: SigningKey) -> dict[str, Any]:
    """The DSSE envelope of a statement (canonical JSON: sorted keys, no spaces)."""
    payload = json.dumps(statement, sort_keys=True, separators=(",", ":")).encode("utf-8")
    return sign_envelope(payload, key.key, key.keyid)


def open_statement(envelope: Mapping[str, Any], trusted: Mapping[str, Any], kind: str, *,
                   where: str) -> tuple[dict[str, Any], str]:
    """The verified statement of ``envelope`` and its signer's keyid; ``AttestationError`` naming ``where``
    when the signature, the statement type or the predicate type is not what it must be."""
    payload, keyid = verify_envelope(envelope, trusted, where=where)
    try:
        stmt = userfiles.parse_bounded(json.loads, payload.decode("utf-8"), where=f"{where}: the signed payload")
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise AttestationError(f"{where}: the signed payload is not JSON") from None
    except userfiles.UserFileError as exc:
        raise AttestationError(str(exc)) from None
    if not isinstance(stmt, dict) or stmt.get("_type") != STATEMENT_TYPE:
        raise AttestationError(f"{where}: not an in-toto Statement v1")
    if stmt.get("predicateType") != predicate_type(kind):
        raise AttestationError(f"{where}: predicate {stmt.get('predicateType')!r}, expected {predicate_type(kind)!r}")
    if not isinstance(stmt.get("subject"), list) or not isinstance(stmt.get("predicate"), dict):
        raise AttestationError(f"{where}: statement without subject list or predicate")
    return stmt, keyid


def subjects(statement: Mapping[str, Any]) -> dict[str, str]:
    """A statement's subjects as name -> SHA-256."""
    out: dict[str, str] = {}
    for s in statement.get("subject") or []:
        name, digest = s.get("name"), (s.get("digest") or {}).get("sha256")
        if not isinstance(name, str) or not isinstance(digest, str):
            raise AttestationError("a statement subject without name or sha256 digest")
        out[name] = digest
    return out


def subject_problems(statement: Mapping[str, Any], actual: Mapping[str, str], *, limit: int = 5) -> list[str]:
    """One line per signed file that is missing or altered, and per file present that was not signed."""
    signed = subjects(statement)
    problems = [f"{n}: missing (it was signed)" for n in sorted(set(signed) - set(actual))]
    problems += [f"{n}: not in the signed statement (added after signing)" for n in sorted(set(actual) - set(signed))]
    problems += [f"{n}: altered after signing (sha256 {actual[n][:12]}, signed {signed[n][:12]})"
                 for n in sorted(set(signed) & set(actual)) if signed[n] != actual[n]]
    if len(problems) > limit:
        problems = problems[:limit] + [f"... and {len(problems) - limit} more"]
    return problems
