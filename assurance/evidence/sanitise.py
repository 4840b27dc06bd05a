"""The allow-list an applicant's report markup passes through (``nh3``, the Rust ``ammonia`` sanitiser): what a
supplied template renders is cleaned as an HTML *fragment* before the toolkit puts it in a section of its own page.

What survives: text, the structural tags of a report section (headings below the title, paragraphs, lists,
tables, figures, details, code), links to anchors of the page only, images only as ``data:`` URIs, and a few
attributes whose values cannot carry markup. What does not: script, style, meta, link, base, iframe, object,
embed, form and every tag not listed; comments (an unclosed ``<!--`` ends with the fragment, never swallows the
page); event handlers, ``style``, ``title`` and every attribute not listed; a class that would dress content as
the toolkit's own first page or gate verdict. The fragment is parsed as HTML5 parses it, so it cannot close the
section it is put in. Then no verdict-text scan is needed: nothing a template says can reach the first page,
hide it or restyle it, and the page's CSS is the toolkit's alone.
"""

from __future__ import annotations

import re
from collections.abc import Collection

TAGS = frozenset({
    "section", "div", "p", "span", "h2", "h3", "h4", "h5", "h6", "ul", "ol", "li", "dl", "dt", "dd",
    "table", "caption", "thead", "tbody", "tfoot", "tr", "th", "td", "a", "code", "pre", "kbd", "samp",
    "strong", "em", "b", "i", "u", "small", "sub", "sup", "br", "hr", "img", "figure", "figcaption",
    "details", "summary", "blockquote", "abbr", "mark",
})
"""Tags a supplied section may use (no ``h1``: the report's one title is the first page's)."""

CLASSES = frozenset({
    "muted", "small", "num", "mono", "sha", "break", "badge", "verified", "failed", "not-verified", "outcome",
    "check", "check-head", "matrix", "results", "fixed", "records", "amlas", "files", "delta", "better", "worse",
    "limits", "cmd", "req", "example", "examples", "compact", "unsafe", "cands", "gallery", "plot", "wide", "msg",
    "full", "reason", "tests", "testlist", "nodeid", "mon", "ci", "first", "deployed", "over",
})
"""Classes of the packaged stylesheet a supplied section may use: layout and state colours of sections. Not the
first page's (``cover``, ``gate``, ``toc``, ``warnings``, ``basis``, ``counts``): supplied markup cannot look like
the toolkit's verdict or its gate problems."""

ATTRIBUTES = {"*": {"id", "class"}, "a": {"href"}, "img": {"src", "alt", "width", "height"},
              "td": {"colspan", "rowspan"}, "th": {"colspan", "rowspan", "scope"}, "details": {"open"},
              "ol": {"start"}}

_ANCHOR = re.compile(r"#[A-Za-z][\w.:-]{0,120}")
_NAME = re.compile(r"[A-Za-z][\w.:-]{0,120}")
_DATA_IMAGE = re.compile(r"data:image/(?:png|jpeg|gif|webp);base64,[A-Za-z0-9+/=\s]*")
_NUMBER = re.compile(r"\d{1,4}")
_PLAIN = re.compile(r"[^<>\"'&]{0,300}")
SUPPLIED_ID_PREFIX = "supplied-"
"""Prefix of an id a supplied section gives an element other than its own section anchors: a supplied element
never takes an anchor of the toolkit's (a requirement's row, a check, the first page)."""


def _attribute_filter(own_ids: Collection[str]):
    def keep(tag: str, attr: str, value: str) -> str | None:
        if attr == "href":
            return value if _ANCHOR.fullmatch(value) else None
        if attr == "src":
            return value if _DATA_IMAGE.fullmatch(value) else None
        if attr == "id":
            if not _NAME.fullmatch(value):
                return None
            return value if value in own_ids else SUPPLIED_ID_PREFIX + value
        if attr == "class":
            kept = [c for c in value.split() if c in CLASSES]
            return " ".join(kept) or None
        if attr in ("colspan", "rowspan", "start", "width", "height"):
            return value if _NUMBER.fullmatch(value) else None
        if attr == "scope":
            return value if value in ("row", "col", "rowgroup", "colgroup") else None
        if attr == "open":
            return ""
        if attr == "alt":  # free text, but never markup characters (the toolkit's last pass reads tags by regex)
            return value if _PLAIN.fullmatch(value) else None
        return None
    return keep


def clean_fragment(markup: str, own_ids: Collection[str] = ()) -> str:
    """``markup`` (a supplied template's output) cleaned to the allow-list above. ``own_ids``: the anchors of the
    sections that template renders (kept as they are, so the table of contents finds them); any other id is
    prefixed with :data:`SUPPLIED_ID_PREFIX`."""
    import nh3

    return nh3.clean(markup, tags=set(TAGS), clean_content_tags={"script", "style", "template", "textarea",
                                                                  "noscript", "title", "xmp", "noembed",
                                                                  "noframes", "iframe", "object", "svg", "math"},
                     attributes={k: set(v) for k, v in ATTRIBUTES.items()},
                     attribute_filter=_attribute_filter(frozenset(own_ids)), strip_comments=True, link_rel=None,
                     url_schemes={"data"})


MAX_ELEMENTS = 20_000
"""Elements a supplied section may hold (counted as tags opened, before it is cleaned): the packaged traceability
matrix, the largest section, has a few thousand; 60 000 nested ones took the PDF renderer minutes and a GB."""
MAX_DEPTH = 48
"""How deeply the elements of a cleaned supplied section may nest (the packaged sections nest under 12 deep; the
PDF renderer recurses on nesting)."""

_OPEN_TAG = re.compile(r"<[A-Za-z]")
_TAG = re.compile(r"<(/?)([a-z][a-z0-9]*)\b[^>]*>")
VOID = frozenset({"br", "hr", "img", "area", "base", "col", "embed", "input", "link", "meta", "source", "track",
                  "wbr"})


def element_count(markup: str) -> int:
    """Tags opened in ``markup`` (an upper bound of its elements, counted without parsing it: linear time)."""
    return sum(1 for _ in _OPEN_TAG.finditer(markup))


def nesting_depth(clean: str) -> int:
    """How deeply the elements of ``clean`` (well-formed markup, as :func:`clean_fragment` writes it) nest; linear
    time, no recursion."""
    depth = deepest = 0
    for m in _TAG.finditer(clean):
        closing, tag = m.group(1), m.group(2)
        if tag in VOID:
            continue
        depth = max(depth - 1, 0) if closing else depth + 1
        deepest = max(deepest, depth)
    return deepest


def bounded_clean(markup: str, own_ids: Collection[str] = (), *, where: str, max_chars: int) -> str:
    """:func:`clean_fragment` of a supplied section's markup within the bounds of one: at most ``max_chars``
    characters, :data:`MAX_ELEMENTS` elements before cleaning, :data:`MAX_DEPTH` levels after. ``ValueError``
    naming ``where`` (the template) and the limit it exceeds."""
    if len(markup) > max_chars:
        raise ValueError(f"{where}: report template refused: it renders {len(markup):,} characters, more than the "
                         f"{max_chars:,} a section may hold")
    n = element_count(markup)
    if n > MAX_ELEMENTS:
        raise ValueError(f"{where}: report template refused: it renders {n:,} elements, more than the "
                         f"{MAX_ELEMENTS:,} a section may hold")
    clean = clean_fragment(markup, own_ids)
    depth = nesting_depth(clean)
    if depth > MAX_DEPTH:
        raise ValueError(f"{where}: report template refused: its elements nest {depth} deep, more than the "
                         f"{MAX_DEPTH} levels a section may")
    return clean


__all__ = ["ATTRIBUTES", "CLASSES", "MAX_DEPTH", "MAX_ELEMENTS", "SUPPLIED_ID_PREFIX", "TAGS", "bounded_clean",
           "clean_fragment", "element_count", "nesting_depth"]
