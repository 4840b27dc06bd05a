"""The restricted identifier profile a class name is held to, and its confusable skeleton (Unicode TS 39, by ICU).

A class name is what the report's first page shows an auditor, and what the certification basis reads to pin a
hazard category (``el.classes.class_names``). A name an auditor cannot read as written must not reach either, so a name
is
held to a profile after Unicode Technical Standard #39 (Unicode Security Mechanisms), with ICU's data (its spoof
checker: ``icu.SpoofChecker``, ICU 77, Unicode 16), not a hand list of look-alikes:

1. the name is NFKC-normalised (full-width ``ｒｏａｄ`` is ``road``);
2. every character is then in TS 39's *recommended* identifier set (``Identifier_Status=Allowed``; ICU's
   ``getRecommendedUnicodeSet``) and of the Latin, Common or Inherited script, or one of the separators ``-``,
   ``_`` and the ASCII space: so no other script (Cyrillic ``г``, Armenian, Cherokee, Greek, Hangul), no
   technical or obsolete Latin letters (the small capitals ``ʀᴏᴀᴅ``), nothing invisible or blank-looking (the
   default-ignorables such as U+200B, the Hangul fillers, the Braille blank U+2800, the other spaces);
3. it holds a letter or a digit, does not start or end with a separator or a space, and passes ICU's
   ``INVISIBLE`` check (no combining mark repeated on one letter).

:func:`skeleton` is TS 39's confusable skeleton from ICU's full ``confusables.txt`` data (``rоad`` with a Cyrillic
``о`` and ``road`` share one; so do ``rn`` and ``m``, ``0`` and ``O``), then case-folded, with the combining marks
dropped (``róad`` reads as ``road``) and the separators one space. ``el.classes.class_names`` compares names by it.

Data and pure functions: ``el`` and ``assurance`` both read it.
"""

from __future__ import annotations

import re
import unicodedata

import icu

ALLOWED_SCRIPTS = ("Latin", "Common", "Inherited")
"""The scripts a class name's characters may belong to (TS 39: one script, Latin, plus Common and Inherited)."""
SEPARATORS = frozenset("-_ ")
"""Separators a name may hold although TS 39's recommended set has not all of them (``class_key`` merges them)."""

_CHECKER = icu.SpoofChecker()
_CHECKER.setChecks(icu.USpoofChecks.INVISIBLE)
_RECOMMENDED = _CHECKER.getRecommendedUnicodeSet()
_SEPARATOR_RUNS = re.compile(r"[\s_\-\u2010-\u2015\u2212\u2043\ufe58\ufe63\uff0d]+")

ICU_VERSION: str = icu.ICU_VERSION
UNICODE_VERSION: str = icu.UNICODE_VERSION
"""The ICU and Unicode versions whose data judge the names (recorded in messages and the docs)."""


def script_of(ch: str) -> str:
    """The Unicode script of one character (``Latin``, ``Cyrillic``, ``Common``, ...), by ICU's data."""
    return icu.Script.getScript(ord(ch)).getName()


def describe(ch: str) -> str:
    """One character as a message names it: ``U+0433 CYRILLIC SMALL LETTER GHE``."""
    return f"U+{ord(ch):04X} {unicodedata.name(ch, 'unnamed')}"


def _why_not(ch: str) -> str | None:
    """Why one (NFKC-normalised) character is outside the profile; None when it is inside."""
    if ch in SEPARATORS:
        return None
    script = script_of(ch)
    if unicodedata.category(ch) in ("Zs", "Zl", "Zp", "Cf", "Cc", "Co", "Cn") or ch in "\u115f\u1160\u3164\uffa0\u2800":
        return f"{describe(ch)} is invisible or blank-looking"
    if script not in ALLOWED_SCRIPTS:
        return f"{describe(ch)} is of the {script} script, not Latin"
    if not _RECOMMENDED.contains(ch):
        return (f"{describe(ch)} is not in Unicode TS 39's recommended identifier set (a technical, obsolete, "
                "symbol or punctuation character)")
    return None


def profile_problem(name: str) -> str | None:
    """Why ``name`` is outside the restricted identifier profile (module docstring), in a few words naming the first
    character at fault; None when it is inside."""
    if not isinstance(name, str):
        return f"a class name must be a string, got {type(name).__name__}"
    text = unicodedata.normalize("NFKC", name)
    for ch in text:
        why = _why_not(ch)
        if why is not None:
            return why
    if not any(unicodedata.category(ch)[0] in "LN" for ch in text):
        return "it holds no letter or digit"
    if text[0] in SEPARATORS or text[-1] in SEPARATORS:
        return "it starts or ends with a separator or a space"
    if _CHECKER.check(text):
        return "a combining mark is repeated on one letter (Unicode TS 39 invisible check)"
    return None


def skeleton(name: str) -> str:
    """What a name looks like: ICU's Unicode TS 39 skeleton (the full confusables data) of the NFKC name,
    case-folded and skeletonised again, combining marks dropped, every run of separators one space."""
    text = _CHECKER.getSkeleton(0, unicodedata.normalize("NFKC", str(name)))
    text = _CHECKER.getSkeleton(0, unicodedata.normalize("NFKC", text.casefold())).casefold()
    text = "".join(ch for ch in unicodedata.normalize("NFKD", text)
                   if not unicodedata.combining(ch) and unicodedata.category(ch) not in ("Cf", "Cc", "Mn", "Me"))
    return _SEPARATOR_RUNS.sub(" ", unicodedata.normalize("NFKC", text)).strip()


__all__ = ["ALLOWED_SCRIPTS", "ICU_VERSION", "SEPARATORS", "UNICODE_VERSION", "describe", "profile_problem",
           "script_of", "skeleton"]
