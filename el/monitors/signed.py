"""Hash-checked JSON documents: the calibration cards, the learned monitor and the out-of-domain gate.

A document is ``{"format": F, "body": {...}, "sha256": H}`` with ``H`` the SHA-256 of the body's
canonical JSON (sorted keys, no spaces, no NaN). Reading checks the format and the hash before any
field is trusted; every problem raises the caller's error class with one line naming the file.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any


def body_sha256(body: dict[str, Any]) -> str:
    """SHA-256 of a document body's canonical JSON."""
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def signed_document(fmt: str, body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a body (format and hash added)."""
    return {"format": fmt, "body": body, "sha256": body_sha256(body)}


def read_signed(path: Path, fmt: str, what: str, error: type[ValueError], *, a: str = "a",
                hint: str = "") -> tuple[dict[str, Any], str]:
    """The checked body of the document at ``path`` and its SHA-256 (format ``fmt``; ``what`` names it
    in messages, ``a`` is its article, ``hint`` follows an unreadable file's message). Raises ``error``."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise error(f"{path}: cannot read the {what}: {exc.strerror or exc}{hint}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise error(f"{path}: not {a} {what} (bad JSON: {exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != fmt or not isinstance(doc.get("body"), dict):
        raise error(f"{path}: not {a} {what} (format {fmt!r} expected)")
    body = doc["body"]
    try:
        digest = body_sha256(body)
    except ValueError as exc:
        raise error(f"{path}: {what} body is not plain JSON ({exc})") from None
    if digest != doc.get("sha256"):
        raise error(f"{path}: {what} altered: SHA-256 of its body is {digest[:12]}..., "
                    f"recorded {str(doc.get('sha256'))[:12]}...")
    return body, digest
