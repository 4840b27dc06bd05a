"""Waivers: accepted deviations from failed requirements (``assurance/waivers.yaml``), and when they expire.

A waiver expires by a date or by a toolkit version, and either is bounded, so that no waiver stands for ever: a
date at most the registry's ``waiver_max_days`` ahead of the report, a version at most the toolkit's next minor
release (:func:`max_expiry_version`: 0.2.0 for toolkit 0.1.x, 1.4.0 for 1.3.x). A new minor release is where the
requirements, targets and evidence are reviewed again, so a waiver must be renewed there (a version expiry of
"999.0.0" is refused as the date 2999-12-31 is).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from assurance import __version__
from el.base import safeyaml

WAIVER_FIELDS = ("id", "reason", "tracked_by", "owner", "expires")


def load_waivers(path: str | Path) -> dict[str, dict[str, str]]:
    """Accepted deviations: requirement id -> {reason, tracked_by, owner, expires} (``assurance/waivers.yaml``).

    ``expires`` is a date (YYYY-MM-DD: the waiver holds until the end of that day) or a toolkit version
    (X.Y.Z: it holds for versions before that one). ValueError naming the file for a malformed file, an
    entry without one of the fields, an expiry that is neither, or a requirement waived twice.
    """
    import yaml

    path = Path(path)
    try:  # a regular file of at most 1 MiB (a FIFO or a device refused before any read), no aliases, dates as text
        data = safeyaml.load_file(path, what="waivers file", loader=_text_dates_loader()) or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        text = str(exc)  # a refusal of the file itself names it already
        raise ValueError(text if text.startswith(f"{path}: ") else f"{path}: unreadable waivers file: {text}") from None
    if not isinstance(data, dict) or not isinstance(data.get("waivers") or [], list):
        raise ValueError(f"{path}: a waivers file is a mapping with a list 'waivers'")
    out: dict[str, dict[str, str]] = {}
    for i, w in enumerate(data.get("waivers") or []):
        if not isinstance(w, dict) or not all(str(w.get(k) or "").strip() for k in WAIVER_FIELDS):
            raise ValueError(f"{path}: waiver {i + 1} needs an id, a reason, tracked_by, an owner and expires "
                             "(a date YYYY-MM-DD or a version X.Y.Z)")
        rid = str(w["id"])
        expires = str(w["expires"]).strip()
        kind, value = _expiry(expires, path, i, rid)
        expires = value.isoformat() if kind == "date" else expires  # 2026-1-5 as 2026-01-05
        if rid in out:
            raise ValueError(f"{path}: {rid} is waived twice")
        out[rid] = {"reason": " ".join(str(w["reason"]).split()), "tracked_by": str(w["tracked_by"]),
                    "owner": str(w["owner"]), "expires": expires}
    return out


def _version_tuple(text: str) -> tuple[int, ...]:
    """A version X.Y.Z as a tuple of integers."""
    return tuple(int(x) for x in text.split("."))


def _text_dates_loader() -> type:
    """The bounded YAML loader keeping dates as written (``2026-02-30`` would fail inside the YAML parser, naming
    neither the file nor the waiver; :func:`_expiry` reads the text)."""
    class TextDates(safeyaml.BoundedSafeLoader):
        pass

    TextDates.add_constructor("tag:yaml.org,2002:timestamp", lambda loader, node: loader.construct_scalar(node))
    return TextDates


def _expiry(expires: str, path: Path, i: int, rid: str | None = None) -> tuple[str, Any]:
    """A waiver's expiry as ('date', date) or ('version', tuple); ValueError naming the file and the waiver (its
    number and, when known, its id)."""
    import re

    which = f"waiver {i + 1}" + (f" ({rid})" if rid else "")
    why = ""
    if m := re.fullmatch(r"(\d{4})-(\d{1,2})-(\d{1,2})", expires):
        try:
            return "date", _dt.date(*(int(g) for g in m.groups()))
        except ValueError as exc:
            why = f": not a date of the calendar ({exc})"
    elif re.fullmatch(r"\d+(\.\d+){0,2}", expires):
        return "version", _version_tuple(expires)
    raise ValueError(f"{path}: {which}: expires must be a date YYYY-MM-DD or a version X.Y.Z, got {expires!r}{why}")


def waiver_expired(waiver: Mapping[str, str], *, today: _dt.date | None = None, version: str = __version__) -> bool:
    """Whether a waiver no longer holds: its date has passed, or this toolkit's version reached its version."""
    kind, value = _expiry(waiver["expires"], Path("waivers"), 0)
    if kind == "date":
        return (today or _dt.datetime.now(_dt.UTC).date()) > value
    return _version_tuple(version) >= value


DEFAULT_MAX_WAIVER_DAYS = 366
"""A waiver dated further ahead than this (from the day of the report) is refused unless the policy says more."""


def max_expiry_version(version: str = __version__) -> tuple[int, int, int]:
    """The furthest version a waiver may expire at under toolkit ``version`` X.Y.Z: the next minor release,
    X.(Y+1).0. Versions compare as tuples of integers (``_version_tuple``), so "0.2" and "0.2.0" are equal."""
    parts = [int(p) if p.isdigit() else 0 for p in (version.split(".") + ["0", "0"])[:2]]
    return parts[0], parts[1] + 1, 0


def _version_text(value: tuple[int, ...]) -> str:
    return ".".join(str(v) for v in value)


def waiver_problems(waivers: Mapping[str, Mapping[str, str]], states: Mapping[str, str], *,
                    owners: list[str] | None = None, max_days: int = DEFAULT_MAX_WAIVER_DAYS,
                    today: _dt.date | None = None, version: str = __version__) -> list[str]:
    """Why waivers cannot stand, one line each: a waiver of an id the registry lacks or of a requirement that
    is verified, an owner not in the declared ``owners`` (when declared), an expiry date more than ``max_days``
    ahead, an expiry version beyond the next minor release of toolkit ``version`` (:func:`max_expiry_version`)."""
    today = today or _dt.datetime.now(_dt.UTC).date()
    out = []
    for rid, w in sorted(waivers.items()):
        if rid not in states:
            out.append(f"a waiver names {rid}, which is not a requirement of the registry")
        elif states[rid] == "verified":  # a not-verified one (e.g. undecidable on a demo run) leaves it unused
            out.append(f"a waiver names {rid}, which is verified: waive only a failed requirement")
        if owners is not None and w.get("owner") not in owners:
            out.append(f"the waiver of {rid} is owned by {w.get('owner')!r}, not one of the declared owners "
                       f"({', '.join(owners) or 'none declared'})")
        kind, value = _expiry(str(w.get("expires")), Path("waivers"), 0)
        if kind == "date" and (value - today).days > max_days:
            out.append(f"the waiver of {rid} expires {value}, more than {max_days} days ahead (the declared maximum)")
        elif kind == "version" and value > (furthest := max_expiry_version(version)):
            out.append(f"the waiver of {rid} expires at version {_version_text(value)}, beyond the next minor "
                       f"release {_version_text(furthest)} of this toolkit ({version}): a version expiry reaches at "
                       "most the next minor release")
    return out
