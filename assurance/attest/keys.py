"""Signing and trusted keys: Ed25519, PEM, kept outside the run.

The signing key is the first of: an explicit path, ``UAV_EL_SIGNING_KEY`` (a path, or the PEM text itself,
as a CI secret provides it), the user's key file ``$XDG_CONFIG_HOME/uav-el/signing-key.pem`` (created,
mode 0600, on first use). A key file that its group or others may read (mode 0644, say) is refused, as ssh
refuses one, with the fix in the message (``chmod 600 PATH``). Its identity is its fingerprint: the SHA-256 of
the raw 32-byte public key, which is also the ``keyid`` of every signature it makes. Trusted keys are PEM public
keys (one file holding one or more, or a folder of ``*.pem`` / ``*.pub``); without any, the local signing key's
own public key is trusted.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from assurance.attest.dsse import AttestationError
from assurance.attest.key_paths import KEY_ENV, default_key_path
from el.base import userfiles

log = logging.getLogger(__name__)

TRUSTED_ENV = "UAV_EL_TRUSTED_KEYS"
_PEM_BLOCK = re.compile(rb"-----BEGIN PUBLIC KEY-----.+?-----END PUBLIC KEY-----", re.S)
MAX_KEY_FILE_BYTES = 1024 * 1024


def fingerprint(public: Ed25519PublicKey) -> str:
    """The SHA-256 (hex) of the raw public key: the keyid of its signatures."""
    raw = public.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()


def public_pem(public: Ed25519PublicKey) -> str:
    """The public key as PEM (SubjectPublicKeyInfo), to hand to an auditor."""
    return public.public_bytes(serialization.Encoding.PEM,
                               serialization.PublicFormat.SubjectPublicKeyInfo).decode("ascii")


@dataclass(frozen=True)
class SigningKey:
    """An Ed25519 private key, where it came from, and its fingerprint."""

    key: Ed25519PrivateKey
    source: str

    @property
    def public(self) -> Ed25519PublicKey:
        return self.key.public_key()

    @property
    def keyid(self) -> str:
        return fingerprint(self.public)


def _private_from_pem(data: bytes, where: str) -> Ed25519PrivateKey:
    try:
        key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError) as exc:
        raise AttestationError(f"{where}: not an unencrypted PEM private key ({exc})") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise AttestationError(f"{where}: a {type(key).__name__}, not an Ed25519 key")
    return key


def _read_small(path: Path, what: str, *, own: bool = False) -> bytes:
    """A key file's bytes through ``el.base.userfiles`` (a regular file of at most ``MAX_KEY_FILE_BYTES``: a FIFO or a
    device refused before any read); AttestationError naming the file. ``own``: the auditor's signing key itself
    (protected against every other reader, and may be a hard link)."""
    if not path.exists() and not path.is_symlink():
        raise AttestationError(f"{path}: {what} not found")
    try:
        return userfiles.read_bytes(path, what=what, max_bytes=MAX_KEY_FILE_BYTES, own=own)
    except userfiles.UserFileError as exc:
        raise AttestationError(str(exc)) from None


def check_private_mode(path: Path) -> None:
    """Refuse a private key file its group or others may read or write (any of the mode bits 077), as ssh does:
    a key others can read is no longer the signer's alone. The message names the fix (``chmod 600 PATH``)."""
    try:
        mode = path.stat().st_mode & 0o777
    except OSError:
        return  # not there: the read that follows names it
    if mode & 0o077:
        raise AttestationError(f"{path}: the signing key is accessible by others (mode {mode:04o}); a private key "
                               f"must be readable by its owner only: run chmod 600 {path}")


def create_key(path: Path) -> SigningKey:
    """A new Ed25519 key written to ``path`` (mode 0600; parent folders created, 0700)."""
    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption())
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(pem)
    userfiles.protect(path)
    return SigningKey(key, str(path))


def load_signing_key(path: str | Path | None = None, *, create: bool = True,
                     outside: str | Path | None = None) -> SigningKey:
    """The signing key (see the module docstring); created at the default path on first use if ``create``.

    ``outside``: a folder the key file must not lie in (the run it signs: a key stored with the evidence
    would let anyone who can edit the evidence re-sign it).
    """
    env = os.environ.get(KEY_ENV, "").strip()
    if path is None and env.startswith("-----BEGIN"):
        return SigningKey(_private_from_pem(env.encode("ascii", "replace"), f"${KEY_ENV}"), f"${KEY_ENV}")
    p = Path(path) if path is not None else Path(env) if env else default_key_path()
    if outside is not None and p.resolve().is_relative_to(Path(outside).resolve()):
        raise AttestationError(f"{p}: the signing key lies inside {outside}; keep it outside the evidence it signs")
    if path is None and not env and not p.exists():
        if not create:
            raise AttestationError(f"{p}: no signing key (give one with --signing-key or ${KEY_ENV})")
        made = create_key(p)
        log.warning("created a signing key %s (fingerprint %s); give its public key to whoever verifies "
                    "your evidence: uav-el keys --public", p, made.keyid[:16])
        return made
    check_private_mode(p)
    userfiles.protect(p)  # no supplied file may read it under another name from now on
    return SigningKey(_private_from_pem(_read_small(p, "signing key", own=True), str(p)), str(p))


def _publics_from_pem(data: bytes, where: str) -> list[Ed25519PublicKey]:
    blocks = _PEM_BLOCK.findall(data)
    if not blocks:
        raise AttestationError(f"{where}: no PEM public key in it")
    keys = []
    for block in blocks:
        try:
            key = serialization.load_pem_public_key(block)
        except ValueError as exc:
            raise AttestationError(f"{where}: a public key that cannot be read ({exc})") from None
        if not isinstance(key, Ed25519PublicKey):
            raise AttestationError(f"{where}: a {type(key).__name__}, not an Ed25519 public key")
        keys.append(key)
    return keys


def load_trusted_keys(spec: str | Path | None = None) -> dict[str, Ed25519PublicKey]:
    """Trusted public keys by keyid, from ``spec`` (file or folder), else ``UAV_EL_TRUSTED_KEYS``, else the
    local signing key's own public key (a user checking their own evidence)."""
    source = spec if spec is not None else os.environ.get(TRUSTED_ENV) or None
    if source is None:
        local = load_signing_key(create=False)
        log.info("no trusted keys given: trusting the local signing key %s only", local.keyid[:16])
        return {local.keyid: local.public}
    p = Path(source)
    files = sorted([*p.glob("*.pem"), *p.glob("*.pub")]) if p.is_dir() else [p]
    if not files:
        raise AttestationError(f"{p}: a folder with no *.pem or *.pub public key")
    trusted: dict[str, Ed25519PublicKey] = {}
    for f in files:
        for key in _publics_from_pem(_read_small(f, "trusted key file"), str(f)):
            trusted[fingerprint(key)] = key
    return trusted
