"""DSSE envelopes (Dead Simple Signing Envelope, v1) signed with Ed25519.

The signature covers the pre-authentication encoding ``PAE(payloadType, payload)`` =
``"DSSEv1" SP len(type) SP type SP len(body) SP body``, so neither the type nor the body can be swapped
without breaking it. The envelope is the JSON ``{"payload", "payloadType", "signatures": [{"keyid", "sig"}]}``
with base64 payload and signatures, as in-toto attestations are distributed.
"""

from __future__ import annotations

import base64
import binascii
import json
from collections.abc import Mapping
from pathlib import Path

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from assurance.files import atomic_write_text
from el.base import userfiles
from el.base.errors import UavElError

INTOTO_PAYLOAD_TYPE = "application/vnd.in-toto+json"
MAX_ENVELOPE_BYTES = 64 * 1024 * 1024
"""An envelope larger than this is refused before it is parsed (a release run's task list is ~1 MB)."""


class AttestationError(UavElError, ValueError):
    """A signature, envelope or statement that is missing, malformed, untrusted or inconsistent."""


def pae(payload_type: str, payload: bytes) -> bytes:
    """The DSSE v1 pre-authentication encoding of a payload and its type."""
    t = payload_type.encode("utf-8")
    return b"DSSEv1 %d %s %d %s" % (len(t), t, len(payload), payload)


def sign_envelope(payload: bytes, key: Ed25519PrivateKey, keyid: str,
                  payload_type: str = INTOTO_PAYLOAD_TYPE) -> dict:
    """An envelope over ``payload`` with one Ed25519 signature by ``key`` (named ``keyid``)."""
    sig = key.sign(pae(payload_type, payload))
    return {"payload": base64.b64encode(payload).decode("ascii"), "payloadType": payload_type,
            "signatures": [{"keyid": keyid, "sig": base64.b64encode(sig).decode("ascii")}]}


def _b64(text: object, what: str, where: str) -> bytes:
    if not isinstance(text, str):
        raise AttestationError(f"{where}: {what} is not a base64 string")
    try:
        return base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise AttestationError(f"{where}: {what} is not valid base64 ({exc})") from None


def verify_envelope(envelope: Mapping, trusted: Mapping[str, Ed25519PublicKey], *, where: str = "envelope",
                    payload_type: str = INTOTO_PAYLOAD_TYPE) -> tuple[bytes, str]:
    """The payload of ``envelope`` and the keyid that signed it, if one of the ``trusted`` keys did.

    ``trusted`` maps keyid to public key. A signature by an unknown key is skipped; the envelope is accepted
    when at least one signature verifies with a trusted key, refused (``AttestationError`` naming ``where``)
    otherwise, or when the type is not ``payload_type``.
    """
    if not isinstance(envelope, Mapping):
        raise AttestationError(f"{where}: not a DSSE envelope (a JSON object)")
    if envelope.get("payloadType") != payload_type:
        raise AttestationError(f"{where}: payloadType {envelope.get('payloadType')!r}, expected {payload_type!r}")
    payload = _b64(envelope.get("payload"), "payload", where)
    sigs = envelope.get("signatures")
    if not isinstance(sigs, list) or not sigs:
        raise AttestationError(f"{where}: no signature")
    keyids = []
    for s in sigs:
        if not isinstance(s, Mapping):
            raise AttestationError(f"{where}: a signature entry is not an object")
        keyid = s.get("keyid")
        keyids.append(str(keyid))
        key = trusted.get(keyid) if isinstance(keyid, str) else None
        if key is None:
            continue
        try:
            key.verify(_b64(s.get("sig"), "sig", where), pae(payload_type, payload))
        except InvalidSignature:
            raise AttestationError(f"{where}: the signature of key {keyid[:16]} does not match its content "
                                   "(altered after signing)") from None
        return payload, keyid
    raise AttestationError(f"{where}: signed by {', '.join(k[:16] for k in keyids)}, none of them a trusted key")


def write_envelope(path: str | Path, envelope: Mapping) -> None:
    """Write an envelope as JSON, atomically."""
    atomic_write_text(path, json.dumps(envelope, indent=1) + "\n")


def read_envelope(path: str | Path) -> dict:
    """Read an envelope file; ``AttestationError`` naming the file when it is missing, too large or not JSON."""
    p = Path(path)
    if not p.is_file():
        raise AttestationError(f"{p}: missing (no signed attestation)")
    if p.stat().st_size > MAX_ENVELOPE_BYTES:
        raise AttestationError(f"{p}: {p.stat().st_size} bytes, more than an attestation may hold")
    try:  # bounded: a link to /proc (a "regular file" of size 0) or a file that grows is refused
        text = userfiles.read_text(p, what="signed attestation", max_bytes=MAX_ENVELOPE_BYTES)
        data = userfiles.parse_bounded(json.loads, text, where=str(p))
    except userfiles.UserFileError as exc:
        raise AttestationError(str(exc)) from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise AttestationError(f"{p}: not a JSON envelope ({exc})") from None
    if not isinstance(data, dict):
        raise AttestationError(f"{p}: not a DSSE envelope (a JSON object)")
    return data
