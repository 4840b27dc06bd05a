"""Where the auditor's signing key lives, and marking it off limits to every supplied file.

Kept apart from :mod:`assurance.attest.keys` (which imports ``cryptography``) so that the command line can protect
the key at start-up without paying for the crypto library: a supplied template, label set or data file that is a
hard link to the key (same device and inode) is then refused by ``el.base.userfiles`` however it is named.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from el.base import userfiles

KEY_ENV = "UAV_EL_SIGNING_KEY"


def default_key_path() -> Path:
    """The user's key file: ``$XDG_CONFIG_HOME/uav-el/signing-key.pem`` (``~/.config`` without it)."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "uav-el" / "signing-key.pem"


def signing_key_paths(explicit: Iterable[str | Path] = ()) -> list[Path]:
    """Every file that may hold the auditor's private key: ``explicit`` ones (``--signing-key``), the path in
    ``$UAV_EL_SIGNING_KEY`` (not when it holds the PEM text itself), and the default key file."""
    paths = [Path(p) for p in explicit if p]
    env = os.environ.get(KEY_ENV, "").strip()
    if env and not env.startswith("-----BEGIN"):
        paths.append(Path(env))
    paths.append(default_key_path())
    return paths


def protect_signing_keys(explicit: Iterable[str | Path] = ()) -> None:
    """Mark each existing file of :func:`signing_key_paths` as the auditor's own (:func:`el.base.userfiles.protect`)."""
    for path in signing_key_paths(explicit):
        userfiles.protect(path)
