"""One bounded reader for every file a user hands the toolkit: system file, label set, hierarchy, poses, waivers,
targets, registry, keys, report templates, fitted records (frame gates, calibration cards, learned monitors).

Whoever wrote such a file may be hostile (an applicant's evidence package is read by an auditor). A plain
``Path.read_text`` of it trusts four things this module does not:

- that it is a regular file: a FIFO blocks the reader for ever, ``/dev/zero`` (or a link to it) never ends.
  The path is refused unless ``stat`` says regular file, then opened with ``O_NONBLOCK`` (an open that cannot hang
  on a FIFO swapped in meanwhile) and refused unless ``fstat`` on that very descriptor says so too, before one
  byte is read;
- that it is small: its size is checked against a cap for its kind before reading, and the read stops at
  ``cap + 1`` bytes, so a file that grows while read is refused too;
- where it lies: a path that resolves (symbolic links followed) under ``/proc``, ``/sys`` or ``/dev`` is refused
  whatever ``stat`` says (``/proc/self/pagemap`` is a "regular file" of size 0 that reads for hundreds of GB;
  ``/proc/self/environ`` holds the CI's secrets), and, given ``within=FOLDER``, a path that resolves outside that
  folder (a symbolic link out of a template folder, which a tar keeps) is refused naming the link and its target.
  The check is made on the path before it is opened and again on what was opened (``/proc/self/fd``), so a link
  swapped in between is caught;
- that it is no other file under another name: a hard link has no target to resolve, so a template folder holding
  a hard link to the auditor's signing key passes every check on where it lies (``tarfile.extractall`` makes one
  from a ``../`` link entry). A file whose content can reach the report as text is refused when it has more than
  one link (``hard_links=True`` admits one where only hashed or decoded bytes are used: weights, ONNX files), and
  no file may be one the auditor protected (:func:`protect`: the signing key), by device and inode of the opened
  descriptor;
- that its structure is shallow: :func:`check_depth` bounds the nesting of a parsed document without recursion,
  :func:`parse_bounded` turns a parser's ``RecursionError`` into a refusal, and :func:`toml_nesting` measures a
  TOML text's nesting (brackets, braces, dotted keys) before ``tomllib`` sees it (``tomllib`` recurses on
  brackets and takes quadratic time on a long dotted key: 20 000 parts, 5 s).

Every refusal is a :class:`UserFileError` (a ``ValueError``: exit 2 at the command line) whose one line names the
file and the problem. ``el`` reads through here itself (label sets); ``assurance`` uses it for the rest.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import stat
import unicodedata
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, BinaryIO, TypeVar

from el.base.errors import UavElError
from el.base.kept import MAX_KEPT_FILE_BYTES, Kept, current
from el.base.kept import read_once as read_once  # the command line's scope (docs/architecture.md section 1.7)

MAX_SETTINGS_BYTES = 1 << 20
"""A settings file (system file, label set, hierarchy, waivers, targets, registry, template): a page, not data."""
MAX_KEY_BYTES = 1 << 20
"""A key file: one PEM private key, or a few public keys."""
MAX_POSES_BYTES = 2 << 20
"""A ``poses.csv`` sidecar: ~20 bytes a frame, so about 100 000 frames of one sequence (an hour at 30 fps is
108 000; each frame is an image of the sequence). Parsed, 2 MiB is ~3 s and ~60 MB here (8 MiB: 14 s, 230 MB)."""
MAX_META_BYTES = 1 << 20
"""A scene's ``meta/*.json`` (pose, seed, style, class shares: about 2 kB), read by the evidence and the campaign:
data folders are not signed, so one may be a FIFO or ``/dev/zero``."""
MAX_RECORD_BYTES = 64 << 20
"""A fitted record (``el.base.records``: frame gate, calibration card, learned monitor). The largest kind is a knn frame
gate, which keeps its training frames' features (frames x dims numbers, ~20 bytes each: the shipped Mahalanobis
gate is 0.65 MB); 64 MiB is ~3 million numbers."""
MAX_MODEL_BYTES = 8 << 30
"""A model file that is hashed (weights, an ONNX file or its external data, a learned monitor): read in chunks, so
memory stays constant; the cap bounds the time (8 GiB: a network of 2 billion float32 parameters; the shipped
network is 8 MB)."""
MAX_HASHED_BYTES = MAX_MODEL_BYTES
"""The default cap of :func:`sha256` (and ``el.base.hashing.sha256_file``): the largest file the toolkit hashes is a
model."""
KERNEL_ROOTS = ("/proc", "/sys", "/dev")
"""File systems that are the kernel's interface, not files: never a user's file, whatever ``stat`` says."""
MAX_DEPTH = 32
"""Nesting of a parsed settings document (the deepest shipped one, a class hierarchy, nests 6 levels)."""

_KINDS = {stat.S_IFIFO: "a FIFO (named pipe)", stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}

T = TypeVar("T")

_PROTECTED: dict[tuple[int, int], tuple[str, str]] = {}
"""(device, inode) -> (path, what it is) of the auditor's own files that no supplied path may open
(:func:`protect`)."""


def protect(path: str | Path, what: str = "the auditor's signing key") -> None:
    """Mark the file at ``path`` (if there is one) as the auditor's own: from now on this process (and children it
    forks) refuses to read it through any other name or link, judged by device and inode of the opened file. A
    path that does not exist is skipped (a link to a file that does not exist yet cannot be made)."""
    try:
        info = os.stat(path)
    except OSError:
        return
    if stat.S_ISREG(info.st_mode):
        _PROTECTED[(info.st_dev, info.st_ino)] = (str(path), what)


def _protected(info: os.stat_result) -> str | None:
    """What the auditor's file ``info`` (an fstat) is, None when it is none: a protected path that no longer is
    that file (removed; its inode may be reused by another) protects nothing any more."""
    entry = _PROTECTED.get((info.st_dev, info.st_ino))
    if entry is None:
        return None
    try:
        now = os.stat(entry[0])
    except OSError:
        now = None
    if now is None or (now.st_dev, now.st_ino) != (info.st_dev, info.st_ino):
        _PROTECTED.pop((info.st_dev, info.st_ino), None)
        return None
    return entry[1]


class UserFileError(UavElError, ValueError):
    """A user's file refused before or while it is read: one line naming the file and the problem."""


def read_bytes(path: str | Path, *, what: str, max_bytes: int, within: str | Path | None = None,
               hard_links: bool = False, own: bool = False) -> bytes:
    """The bytes of the regular file ``path`` (a ``what``, e.g. "waivers file": how messages name it), at most
    ``max_bytes`` of them.

    Refused (``UserFileError``) without blocking and before any read: a path that is missing or cannot be
    opened, anything but a regular file (a FIFO, a device, a socket, a folder; a symbolic link is followed and
    judged by what it points at), a path resolving under ``/proc``, ``/sys`` or ``/dev`` (:data:`KERNEL_ROOTS`),
    with ``within`` a path resolving outside that folder (:func:`check_path`), a file over ``max_bytes``, a file
    with more than one link unless ``hard_links``, a file the auditor protected (:func:`protect`) unless ``own``
    (the auditor reading their own key). A file that grows past the cap while read is refused too: at most
    ``max_bytes + 1`` bytes are ever read.
    """
    p = Path(path)
    kept = _kept(p, what, within, max_bytes, hard_links=hard_links, own=own)
    if kept is not None:
        return kept.data
    once = current()
    key = once.key(p, within) if once is not None else None
    try:
        fd = _open_regular(p, what, within, hard_links=hard_links, own=own)
    except OSError as exc:
        raise _os_refusal(p, what, exc) from None
    try:
        _check_size(p, os.fstat(fd), max_bytes, what)
        data = _read_at_most(fd, max_bytes + 1)
    except OSError as exc:
        raise _os_refusal(p, what, exc) from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise UserFileError(f"{p}: grew past the limit of {max_bytes} bytes for a {what} while read")
    if key is not None and once is not None:
        once.keep(key, data)
    return data


def sha256(path: str | Path, *, what: str = "file", max_bytes: int = MAX_HASHED_BYTES,
           within: str | Path | None = None, chunk: int = 1 << 22) -> str:
    """Hex SHA-256 of the regular file ``path``, read in chunks of ``chunk`` bytes (memory stays constant), refused
    as :func:`read_bytes` refuses (a FIFO, a device, ``/proc``, ``/sys``, ``/dev``, outside ``within``, over
    ``max_bytes``, also while read, a protected file) but for hard links: only the hash leaves here, so a
    deduplicated data set or model store is hashed as it is. A missing or unopenable file raises the ``OSError``
    itself (``FileNotFoundError``: as ``open`` would), so callers that handle those keep working."""
    p = Path(path)
    kept = _kept(p, what, within, max_bytes, hard_links=True, own=False)
    if kept is not None:
        return kept.sha256()
    once = current()
    key = once.key(p, within) if once is not None else None
    fd = _open_regular(p, what, within, hard_links=True)
    try:
        size = os.fstat(fd).st_size
        _check_size(p, os.fstat(fd), max_bytes, what)
        h, seen, blocks = hashlib.sha256(), 0, []
        keep = key is not None and size <= MAX_KEPT_FILE_BYTES
        while block := os.read(fd, min(chunk, max_bytes + 1 - seen) or 1):
            seen += len(block)
            if seen > max_bytes:
                raise UserFileError(f"{p}: grew past the limit of {max_bytes} bytes for a {what} while read")
            h.update(block)
            if keep:
                blocks.append(block)
    finally:
        os.close(fd)
    if key is not None and keep and once is not None:
        once.keep(key, b"".join(blocks), h.hexdigest())
    return h.hexdigest()


def _kept(p: Path, what: str, within: str | Path | None, max_bytes: int, *, hard_links: bool,
          own: bool) -> Kept | None:
    """The bytes this command already read of ``p`` (:func:`read_once`), after the checks a read makes, by ``stat``
    (where it resolves, regular, its links and identity, its size); None when not kept (or outside a scope)."""
    once = current()
    if once is None:
        return None
    key = once.key(p, within)
    kept = once.files.get(key) if key is not None else None
    if kept is None:
        return None
    info = os.stat(p)
    _check_regular(p, info, what)
    check_path(p, what=what, within=within)
    if not own:
        _check_identity(p, info, what, hard_links)
    _check_size(p, info, max_bytes, what)
    return kept


def open_binary(path: str | Path, *, what: str, within: str | Path | None = None,
                hard_links: bool = False) -> BinaryIO:
    """A read-only binary file object of the regular file ``path``, refused as :func:`read_bytes` refuses but for
    the size (no cap: for a file read in bounded pieces, e.g. a flight log of GBs, line by line). The checks are on
    the descriptor the object reads, so a file swapped in after a check is not read."""
    p = Path(path)
    try:
        fd = _open_regular(p, what, within, hard_links=hard_links)
    except OSError as exc:
        raise _os_refusal(p, what, exc) from None
    return os.fdopen(fd, "rb")


def _check_size(p: Path, info: os.stat_result, max_bytes: int, what: str) -> None:
    """Refuse ``p`` when ``info`` (its fstat) says it is larger than ``max_bytes``, before any read."""
    if info.st_size > max_bytes:
        raise UserFileError(f"{p}: {info.st_size} bytes exceeds the limit of {max_bytes} bytes for a {what}")


def _os_refusal(p: Path, what: str, exc: OSError) -> UserFileError:
    if isinstance(exc, FileNotFoundError):
        return UserFileError(f"{p}: cannot read {what}: no such file")
    return UserFileError(f"{p}: cannot read {what}: {exc.strerror or exc}")


def _open_regular(p: Path, what: str, within: str | Path | None, *, hard_links: bool = False,
                  own: bool = False) -> int:
    """A read-only descriptor of the regular file ``p``, checked before it is opened (``stat``: a device is not
    even opened, as opening one may act on it; where it resolves: :func:`check_path`) and after (``fstat`` and the
    path of what was opened, if the path changed meanwhile; its links and identity: :func:`_check_identity`).
    ``OSError`` as raised; refusals as UserFileError."""
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    _check_regular(p, os.stat(p), what)
    check_path(p, what=what, within=within)
    fd = os.open(p, flags)
    try:
        info = os.fstat(fd)
        _check_regular(p, info, what)  # what was opened, if the path changed since the stat
        if not own:
            _check_identity(p, info, what, hard_links)
        opened = _fd_path(fd)
        if opened is not None:  # where what was opened lies (a link swapped in after the check above)
            _check_location(p, Path(opened), what, within)
    except BaseException:
        os.close(fd)
        raise
    return fd


def _check_identity(p: Path, info: os.stat_result, what: str, hard_links: bool) -> None:
    """Refuse the opened file ``p`` (``info``: its fstat) when it is one the auditor protected (:func:`protect`),
    whatever name or link reached it, or, unless ``hard_links``, when it has more than one link: a hard link has no
    target to resolve, so no check of where a path lies can see that it is another file's second name."""
    mine = _protected(info)
    if mine is not None:
        raise UserFileError(f"{p}: is {mine} under another name (a hard link to it, or its own path): a {what} may "
                            "never be the auditor's own file")
    if not hard_links and info.st_nlink > 1:
        raise UserFileError(f"{p}: a file with {info.st_nlink} links (a hard link): a {what} must have one, as a "
                            "hard link may be another file's second name (copy it instead: cp FILE NEW && mv NEW "
                            "FILE)")


def _fd_path(fd: int) -> str | None:
    """The path of what ``fd`` refers to (Linux: ``/proc/self/fd``), None where the system does not say."""
    try:
        target = os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return None
    return target if target.startswith("/") else None


def check_path(path: str | Path, *, what: str, within: str | Path | None = None) -> Path:
    """The real path of ``path`` (every symbolic link followed), or ``UserFileError`` when it is no place for a
    user's file: under ``/proc``, ``/sys`` or ``/dev`` (:data:`KERNEL_ROOTS`), or, with ``within`` (a folder),
    outside that folder (itself resolved): a symbolic link leading out of it is named with its target, as is a
    ``..`` path. Nothing is opened or read; a path that does not exist is not refused here (reading it is)."""
    p = Path(path)
    real = Path(os.path.realpath(p))
    _check_location(p, real, what, within)
    return real


def _check_location(p: Path, real: Path, what: str, within: str | Path | None) -> None:
    for root in KERNEL_ROOTS:
        if real == Path(root) or real.is_relative_to(root):
            how = f"a symbolic link to {_link_target(p)}, which resolves to {real}" if p.is_symlink() else \
                f"resolves to {real}"
            raise UserFileError(f"{p}: {how}, under {root}: a {what} must be a regular file, not a file of the "
                                f"kernel's {root} interface")
    if within is None:
        return
    folder = Path(os.path.realpath(within))
    if real == folder or not real.is_relative_to(folder):
        how = f"a symbolic link to {_link_target(p)}" if p.is_symlink() else f"resolves to {real}"
        raise UserFileError(f"{p}: {how}, outside its folder {within}: a {what} must lie inside its folder "
                            "(a symbolic link out of it is refused)")


def _link_target(p: Path) -> str:
    try:
        return os.readlink(p)
    except OSError:
        return str(os.path.realpath(p))


def _check_regular(p: Path, info: os.stat_result, what: str) -> None:
    """Refuse ``p`` unless ``info`` (its stat) says regular file, naming what it is instead."""
    if not stat.S_ISREG(info.st_mode):
        kind = _KINDS.get(stat.S_IFMT(info.st_mode), "not a regular file")
        raise UserFileError(f"{p}: {kind}, not a regular file (a {what} must be a regular file)")


def not_regular(path: str | Path, *, what: str, within: str | Path | None = None) -> str | None:
    """Why ``path`` cannot be read as a ``what`` (one line naming it), judged by ``stat`` and where it resolves
    (:func:`check_path`: ``/proc``, ``/sys``, ``/dev``, outside ``within``), so without opening or reading it; None
    for a regular file. For a check that a file named in settings is there, before it is read: "no such file" for
    nothing at all, else what it is instead (a FIFO is not reported as missing)."""
    p = Path(path)
    try:
        _check_regular(p, os.stat(p), what)
        check_path(p, what=what, within=within)
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


def read_text(path: str | Path, *, what: str, max_bytes: int, encoding: str = "utf-8",
              within: str | Path | None = None) -> str:
    """:func:`read_bytes`, decoded (``encoding``; ``utf-8-sig`` drops a byte-order mark); text that does not
    decode is refused naming the byte. Text reaches the report: a hard link is refused."""
    data = read_bytes(path, what=what, max_bytes=max_bytes, within=within)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise UserFileError(f"{path}: the {what} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def read_json(path: str | Path, *, what: str, max_bytes: int, within: str | Path | None = None,
              max_depth: int = MAX_DEPTH) -> Any:
    """:func:`read_text`, parsed as JSON nested at most ``max_depth`` deep (:func:`parse_bounded`); text that is
    not JSON is refused too (``UserFileError`` naming the file)."""
    import json

    text = read_text(path, what=what, max_bytes=max_bytes, within=within)
    try:
        return parse_bounded(json.loads, text, where=str(path), max_depth=max_depth)
    except json.JSONDecodeError as exc:
        raise UserFileError(f"{path}: the {what} is not valid JSON ({exc})") from None


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


def _nodes(doc: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """Every (dotted key, value) of a parsed document, the document itself first (key ``prefix``); iterative (a
    deep one cannot exhaust the stack), keys in document order."""
    stack: list[tuple[str, Any]] = [(prefix, doc)]
    while stack:
        key, node = stack.pop()
        yield key, node
        if isinstance(node, dict):
            stack.extend(reversed([(f"{key}.{k}" if key else str(k), v) for k, v in node.items()]))
        elif isinstance(node, list | tuple):
            stack.extend(reversed([(f"{key}[{i}]", v) for i, v in enumerate(node)]))


def non_finite(doc: Any, prefix: str = "") -> tuple[str, float] | None:
    """The first (dotted key, value) of a parsed document holding NaN or an infinity, None when every number is
    finite; iterative, keys in document order. A settings file means numbers: ``nan`` and ``inf`` in one are a
    mistake or an attack (NaN compares false with every bound, so a range check alone lets it through)."""
    for key, node in _nodes(doc, prefix):
        if isinstance(node, float) and not math.isfinite(node):
            return key or "(top level)", node
    return None


def hidden_character(doc: Any, prefix: str = "") -> tuple[str, str] | None:
    """The first (dotted key, ``U+XXXX``) of a parsed document whose keys or strings hold a control or format
    character (Unicode categories Cc and Cf: a right-to-left override, a zero-width joiner; tab and line breaks
    excepted), None when there is none. Such a character makes a text display other than it reads (``DELIAF``
    shown as ``FAILED``), so a settings file whose texts reach a report may hold none."""
    for key, node in _nodes(doc, prefix):
        texts = [node] if isinstance(node, str) else list(node) if isinstance(node, dict) else []
        for text in texts:
            bad = next((ch for ch in str(text) if ch not in "\t\n\r"
                        and unicodedata.category(ch) in ("Cc", "Cf")), None)
            if bad is not None:
                return key or "(top level)", f"U+{ord(bad):04X}"
    return None
