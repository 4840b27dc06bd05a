"""The identity of the toolkit's code as it runs: its version, a SHA-256 over the package files as installed, and a
git commit only when it runs from its own checkout (docs/architecture.md 4.6).

An installed wheel has no git commit of its own; the folder it sits in may well be inside some other git
repository (a user's project, a CI workspace), whose HEAD says nothing about this code. So the commit is read
only when the folder holding the ``el`` and ``assurance`` packages is the top of a git checkout whose
``pyproject.toml`` names this project; otherwise the code is identified by version and file hash alone.
"""

from __future__ import annotations

import hashlib
import logging
import re
import subprocess
from collections.abc import Sequence
from importlib import metadata, util
from pathlib import Path
from typing import Any

from assurance import __version__
from el.base.hashing import sha256_file

log = logging.getLogger(__name__)

PROJECT = "uav-el-assurance"
"""The distribution name (``pyproject.toml`` ``[project] name``)."""
PACKAGES = ("el", "assurance")
"""What the code hash covers: the flight code and the harness, with the packaged requirement checks."""
SUFFIXES = (".py", ".yaml", ".yml", ".j2", ".css", ".json", ".toml", ".csv", ".typed")
"""The files of a package the hash covers (source, templates, registry, schemas, cards; not the weights, which
a run identifies by their own SHA-256)."""


def package_dirs() -> list[Path]:
    """The folders of the installed ``el`` and ``assurance`` packages (found without importing them) and of the
    report's templates (``evidence_templates``, beside ``assurance``)."""
    out = []
    for name in PACKAGES:
        spec = util.find_spec(name)
        locations = list(spec.submodule_search_locations or []) if spec else []
        if locations:
            out.append(Path(locations[0]).resolve())
    templates = install_root() / "evidence_templates"  # the report's packaged templates, beside assurance
    if templates.is_dir():
        out.append(templates.resolve())
    return out


def install_root() -> Path:
    """The folder that holds the ``assurance`` package (site-packages for a wheel, the checkout when editable)."""
    return Path(__file__).resolve().parents[1]


def tree_sha256(roots: Sequence[Path], *, suffixes: Sequence[str] = SUFFIXES,
                base: Path | None = None) -> tuple[str, int]:
    """SHA-256 over the files under ``roots`` with one of ``suffixes`` (relative path and content hash, sorted;
    ``__pycache__`` left out); (hash, file count). Paths are relative to ``base`` (default: the install root)."""
    base = base or install_root()
    files = sorted(p for r in roots if r.is_dir() for p in r.rglob("*")
                   if p.is_file() and p.suffix in suffixes and "__pycache__" not in p.parts)
    h = hashlib.sha256()
    for p in files:
        h.update(f"{p.relative_to(base).as_posix()}:{sha256_file(p)}\n".encode())
    return h.hexdigest(), len(files)


def version() -> str:
    """The installed distribution's version (the package's ``__version__`` when it is not installed)."""
    try:
        return metadata.version(PROJECT)
    except metadata.PackageNotFoundError:
        return __version__


def own_checkout() -> Path | None:
    """The toolkit's own git checkout when the code runs from one (the install root is the top of a work tree
    and its pyproject.toml names this project), else None: never an enclosing repository."""
    root = install_root()
    pyproject = root / "pyproject.toml"
    if not pyproject.is_file() or not (root / ".git").exists():
        return None
    try:
        text = pyproject.read_text(encoding="utf-8")
    except OSError:
        return None
    if not re.search(rf'^name\s*=\s*"{re.escape(PROJECT)}"\s*$', text, re.MULTILINE):
        return None
    try:
        top = subprocess.run(["git", "-C", str(root), "rev-parse", "--show-toplevel"], capture_output=True,
                             text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return root if top and Path(top).resolve() == root else None


def git_commit() -> str | None:
    """The commit of the toolkit's own checkout (with '-dirty' if it has changes), or None (installed, or no git)."""
    root = own_checkout()
    if root is None:
        return None
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("-dirty" if dirty else "")


def code_sha256() -> str:
    """The hash of the code as it runs (``PACKAGES`` under the install root): what requirement results bind."""
    return tree_sha256(package_dirs())[0]


def code_identity() -> dict[str, Any]:
    """Version, file hash and count, where the code runs from (``checkout`` or ``installed``) and the git commit
    (None when installed)."""
    sha, files = tree_sha256(package_dirs())
    commit = git_commit()
    ident = {"version": version(), "sha256": sha, "files": files,
             "source": "checkout" if own_checkout() is not None else "installed", "git_commit": commit}
    log.debug("code identity: %s", ident)
    return ident
