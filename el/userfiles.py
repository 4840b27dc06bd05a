"""One bounded reader for every file a user hands the toolkit: system file, label set, hierarchy, poses, waivers,
targets, registry, keys, report templates, fitted records (frame gates, calibration cards, learned monitors).

Whoever wrote such a file may be hostile (an applicant's evidence package is read by an auditor). A plain
``Path.read_text`` of it trusts three things this module does not:

- that it is a regular file: a FIFO blocks the reader for ever, ``/dev/zero`` (or a link to it) never ends.
  The path is refused unless ``stat`` says regular file, then opened with ``O_NONBLOCK`` (an open that cannot hang
  on a FIFO swapped in meanwhile) and refused unless ``fstat`` on that very descriptor says so too, before one
  byte is read;
- that it is small: its size is checked against a cap for its kind before reading, and the read stops at
  ``cap + 1`` bytes, so a file that grows while read is refused too;
- that its structure is shallow: :func:`check_depth` bounds the nesting of a parsed document without recursion,
  :func:`parse_bounded` turns a parser's ``RecursionError`` into a refusal, and :func:`toml_nesting` measures a
  TOML text's nesting (brackets, braces, dotted keys) before ``tomllib`` sees it (``tomllib`` recurses on
  brackets and takes quadratic time on a long dotted key: 20 000 parts, 5 s).

Every refusal is a :class:`UserFileError` (a ``ValueError``: exit 2 at the command line) whose one line names the
file and the problem. ``el`` reads through here itself (label sets); ``assurance`` uses it for the rest.
"""

from __future__ import annotations

import math
import os
import re
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from el.errors import UavElError

MAX_SETTINGS_BYTES = 1 << 20
"""A settings file (system file, label set, hierarchy, waivers, targets, registry, template): a page, not data."""
MAX_KEY_BYTES = 1 << 20
"""A key file: one PEM private key, or a few public keys."""
MAX_POSES_BYTES = 2 << 20
"""A ``poses.csv`` sidecar: ~20 bytes a frame, so about 100 000 frames of one sequence (an hour at 30 fps is
108 000; each frame is an image of the sequence). Parsed, 2 MiB is ~3 s and ~60 MB here (8 MiB: 14 s, 230 MB)."""
MAX_RECORD_BYTES = 64 << 20
"""A fitted record (``el.records``: frame gate, calibration card, learned monitor). The largest kind is a knn frame
gate, which keeps its training frames' features (frames x dims numbers, ~20 bytes each: the shipped Mahalanobis
gate is 0.65 MB); 64 MiB is ~3 million numbers."""
MAX_DEPTH = 32
"""Nesting of a parsed settings document (the deepest shipped one, a class hierarchy, nests 6 levels)."""

_KINDS = {stat.S_IFIFO: "a FIFO (named pipe)", stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}

T = TypeVar("T")


class UserFileError(UavElError, ValueError):
    """A user's file refused before or while it is read: one line naming the file and the problem."""


def read_bytes(path: str | Path, *, what: str, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` (a ``what``, e.g. "waivers file": how messages name it), at most
    ``max_bytes`` of them.

    Refused (``UserFileError``) without blocking and before any read: a path that is missing or cannot be
    opened, anything but a regular file (a FIFO, a device, a socket, a folder; a symbolic link is followed and
    judged by what it points at), a file over ``max_bytes``. A file that grows past the cap while read is
    refused too: at most ``max_bytes + 1`` bytes are ever read.
    """
    p = Path(path)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        _check_regular(p, os.stat(p), what)  # a device is not even opened (opening one may act on it)
        fd = os.open(p, flags)
    except FileNotFoundError:
        raise UserFileError(f"{p}: cannot read {what}: no such file") from None
    except OSError as exc:
        raise UserFileError(f"{p}: cannot read {what}: {exc.strerror or exc}") from None
    try:
        info = os.fstat(fd)
        _check_regular(p, info, what)  # what was opened, if the path changed since the stat
        if info.st_size > max_bytes:
            raise UserFileError(f"{p}: {info.st_size} bytes exceeds the limit of {max_bytes} bytes for a {what}")
        data = _read_at_most(fd, max_bytes + 1)
    except OSError as exc:
        raise UserFileError(f"{p}: cannot read {what}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise UserFileError(f"{p}: grew past the limit of {max_bytes} bytes for a {what} while read")
    return data


def _check_regular(p: Path, info: os.stat_result, what: str) -> None:
    """Refuse ``p`` unless ``info`` (its stat) says regular file, naming what it is instead."""
    if not stat.S_ISREG(info.st_mode):
        kind = _KINDS.get(stat.S_IFMT(info.st_mode), "not a regular file")
        raise UserFileError(f"{p}: {kind}, not a regular file (a {what} must be a regular file)")


def not_regular(path: str | Path, *, what: str) -> str | None:
    """Why ``path`` cannot be read as a ``what`` (one line naming it), judged by ``stat`` alone, so without opening
    or reading it; None for a regular file. For a check that a file named in settings is there, before it is read:
    "no such file" for nothing at all, else what it is instead (a FIFO is not reported as missing)."""
    p = Path(path)
    try:
        _check_regular(p, os.stat(p), what)
    except FileNotFoundError:
        return f"{p}: no such file"
    except OSError as exc:
        return f"{p}: cannot read {what}: {exc.strerror or exc}"
    except UserFileError as exc:
        return str(exc)
    return None


def _read_at_most(fd: int, limit: int) -> bytes:
    """Up to ``limit`` bytes from ``fd`` (fewer at the end of the file)."""
    chunks, left = [], limit
    while left > 0:
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            break
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def read_text(path: str | Path, *, what: str, max_bytes: int, encoding: str = "utf-8") -> str:
    """:func:`read_bytes`, decoded (``encoding``; ``utf-8-sig`` drops a byte-order mark); text that does not
    decode is refused naming the byte."""
    data = read_bytes(path, what=what, max_bytes=max_bytes)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise UserFileError(f"{path}: the {what} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def parse_bounded(parse: Callable[[str], T], text: str, *, where: str, max_depth: int = MAX_DEPTH) -> T:
    """``parse(text)``, refused when the parser runs out of stack (a document nested thousands deep) or the result
    nests deeper than ``max_depth`` (``UserFileError`` naming ``where``). The parser's own errors pass through."""
    try:
        doc = parse(text)
    except RecursionError:
        raise UserFileError(f"{where}: nested too deeply to read (more than {max_depth} levels allowed)") from None
    check_depth(doc, where=where, max_depth=max_depth)
    return doc


def check_depth(doc: Any, *, where: str, max_depth: int = MAX_DEPTH) -> None:
    """Refuse a parsed document (dicts and lists) nesting deeper than ``max_depth``; iterative, so a deep one
    cannot exhaust the stack here."""
    stack: list[tuple[Any, int]] = [(doc, 0)]
    while stack:
        node, depth = stack.pop()
        children = node.values() if isinstance(node, dict) else node if isinstance(node, list | tuple) else ()
        for child in children:
            if isinstance(child, dict | list | tuple):
                if depth + 1 > max_depth:
                    raise UserFileError(f"{where}: nested more than {max_depth} levels deep")
                stack.append((child, depth + 1))


# Strings and comments of a TOML text, each consumed whole (multi-line forms first, so that ``"""`` is not read as
# an empty string and a quote). An unterminated one runs to the end of its line (or of the text): every match
# consumes what it started, so the scan is linear whatever the text. What is left holds every bracket, brace and
# dot that structures the document; each string left is ``s``, so that a dotted key of quoted parts still counts.
_TOML_SKIP = re.compile(r'"""(?:[^"\\]++|\\[\s\S]|"(?!""))*+(?:""")?|\'\'\'[\s\S]*?(?:\'\'\'|\Z)'
                        r'|"(?:[^"\\\n]++|\\.)*+"?|\'[^\'\n]*+\'?|#[^\n]*+')
_TOML_OPEN_CLOSE = re.compile(r"[\[\]{}]")
_TOML_DOTTED = re.compile(r"(?<![\w-])[\w-]++(?:[ \t]*+\.[ \t]*+[\w-]++)++")  # never from mid-word


def toml_nesting(text: str, *, limit: int = MAX_DEPTH) -> int:
    """How deeply a TOML text nests: the deepest run of brackets and braces, or the most parts of a dotted key,
    whichever is more (a number such as ``1.5`` counts 2); counting stops past ``limit`` (``limit + 1`` is
    returned). Linear time, no recursion; strings and comments are skipped, so a bracket inside a string does not
    count."""
    bare = _TOML_SKIP.sub("s", text)
    deepest = depth = 0
    for m in _TOML_OPEN_CLOSE.finditer(bare):
        depth = depth + 1 if m.group() in "[{" else max(depth - 1, 0)
        if depth > limit:
            return limit + 1
        deepest = max(deepest, depth)
    for m in _TOML_DOTTED.finditer(bare):
        deepest = max(deepest, m.group().count(".") + 1)
        if deepest > limit:
            return limit + 1
    return deepest


def non_finite(doc: Any, prefix: str = "") -> tuple[str, float] | None:
    """The first (dotted key, value) of a parsed document holding NaN or an infinity, None when every number is
    finite; iterative, keys in document order. A settings file means numbers: ``nan`` and ``inf`` in one are a
    mistake or an attack (NaN compares false with every bound, so a range check alone lets it through)."""
    stack: list[tuple[str, Any]] = [(prefix, doc)]
    while stack:
        key, node = stack.pop()
        if isinstance(node, float) and not math.isfinite(node):
            return key or "(top level)", node
        if isinstance(node, dict):
            stack.extend(reversed([(f"{key}.{k}" if key else str(k), v) for k, v in node.items()]))
        elif isinstance(node, list | tuple):
            stack.extend(reversed([(f"{key}[{i}]", v) for i, v in enumerate(node)]))
    return None
