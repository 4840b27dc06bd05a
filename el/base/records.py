"""Hash-checked JSON records: the calibration cards, the learned monitor and the out-of-domain gate.

A document is ``{"format": F, "body": {...}, "sha256": H}`` with ``H`` the SHA-256 of the body's
canonical JSON (sorted keys, no spaces, no NaN). Reading checks the format and the hash before any
field is trusted; every problem raises the record's error class with one line naming the file.
:class:`HashedRecord` is the one base of the three record kinds: reading, writing and the check that a
record is used with the segmentation network it was fitted on (``body["weights"]["sha256"]``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from el.base.userfiles import MAX_RECORD_BYTES, UserFileError, parse_bounded, read_text


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
    in messages, ``a`` is its article, ``hint`` follows an unreadable file's message). Raises ``error``.

    A record may be an applicant's (``--gate``, ``[monitor] calibration``), so it is read through the bounded
    reader (``el.base.userfiles``): a FIFO, a device or a file over ``MAX_RECORD_BYTES`` is refused before it is read,
    and JSON nested too deeply to parse is refused, never a ``RecursionError``."""
    try:
        doc = parse_bounded(json.loads, read_text(path, what=what, max_bytes=MAX_RECORD_BYTES), where=str(path))
    except UserFileError as exc:
        raise error(f"{exc}{hint}") from None
    except json.JSONDecodeError as exc:
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


def record_body(path: str | Path) -> dict[str, Any] | None:
    """A card's or record's body as the file says (its ``body``, or the whole document when it has none), read
    bounded and NOT checked (format and hash: :func:`read_signed` checks); None when unreadable. For reports that
    describe a record a run's manifest names, whatever state it is in."""
    try:
        doc = json.loads(read_text(path, what="record", max_bytes=MAX_RECORD_BYTES))
    except (OSError, ValueError):  # UserFileError is a ValueError
        return None
    return doc.get("body", doc) if isinstance(doc, dict) else None


def weights_sha256_of(model: Any) -> str | None:
    """The identity a segmentation model reports for its weights (``weights_sha256``; None when it has none)."""
    value = getattr(model, "weights_sha256", None)
    return value if isinstance(value, str) and value else None


def network_identities(model: Any) -> tuple[str, ...]:
    """The identities a record fitted on a network may name for ``model``: its ``weights_sha256`` and, for the
    packaged ONNX export of the shipped weights, those weights' (``source_weights_sha256``, which only the
    package's own engine record sets: ``el.segmentation.onnx_engine.shipped_export_source``)."""
    found = (weights_sha256_of(model), getattr(model, "source_weights_sha256", None))
    return tuple(v for v in found if isinstance(v, str) and v)


def short(digest: str | None) -> str:
    """The first 12 hex digits of a digest and an ellipsis, or ``none``."""
    return f"{digest[:12]}..." if digest else "none"


@dataclass(frozen=True)
class HashedRecord:
    """A checked record: where it was read, the SHA-256 of its body, and the body.

    Subclasses set :attr:`FORMAT`, :attr:`WHAT` (how messages name it) and :attr:`ERROR`, and read their
    fields from the body after :meth:`read_body` has checked format and hash.
    """

    FORMAT: ClassVar[str] = ""
    WHAT: ClassVar[str] = "record"
    ARTICLE: ClassVar[str] = "a"
    ERROR: ClassVar[type[ValueError]] = ValueError

    path: str
    sha256: str
    body: dict[str, Any]

    @classmethod
    def document(cls, body: dict[str, Any]) -> dict[str, Any]:
        """The JSON document of a body (format and hash added), as a fitting command writes it."""
        return signed_document(cls.FORMAT, body)

    @classmethod
    def read_body(cls, path: str | Path, *, hint: str = "") -> tuple[dict[str, Any], str]:
        """The checked body of the file at ``path`` and its SHA-256; :attr:`ERROR` naming the file."""
        return read_signed(Path(path), cls.FORMAT, cls.WHAT, cls.ERROR, a=cls.ARTICLE, hint=hint)

    @property
    def network_sha256(self) -> str | None:
        """SHA-256 of the segmentation weights the record was fitted on (None: not recorded)."""
        weights = self.body.get("weights")
        return weights.get("sha256") if isinstance(weights, dict) else None

    def check_network(self, segmenter: Any) -> None:
        """Refuse a segmentation network the record was not fitted on: the segmenter's ``weights_sha256`` must
        be the one the record holds. A network that cannot say which it is (no hash), and a record that does
        not say, are refused too: a threshold or a feature scale measured on one network means nothing on
        another, and two unidentified networks cannot be told apart.
        """
        have = weights_sha256_of(segmenter)
        want = self.network_sha256
        if not (isinstance(want, str) and want and want in network_identities(segmenter)):
            raise self.ERROR(f"{self.path}: {self.WHAT} fitted on network {short(want)}, but the "
                             f"segmenter runs {short(have)}: refit it for this network"
                             + ("" if want else " (the record names no network)"))
