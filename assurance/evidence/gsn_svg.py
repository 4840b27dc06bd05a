"""The safety argument drawn as SVG, pure Python: a left-to-right tree per page (the top goal with its context and
strategies, then one page per strategy), GSN shapes, verdict colours. No Graphviz: the report must draw the same
figure on every machine without a system package, and a tree needs no general graph layout."""

from __future__ import annotations

import base64
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import escape

from assurance.evidence.argument import Node
from assurance.evidence.navigation import anchor

FONT, LINE, PAD, GAP_X, GAP_Y, MAX_LINES = 10, 12.5, 6, 36, 8, 4
WIDTH = {"Goal": 250, "Strategy": 230, "Solution": 270, "Context": 250, "Assumption": 230, "Justification": 250}
COLOURS = {"verified": ("#e8f5e9", "#2e7d32"), "failed": ("#fdecea", "#c62828"), "waived": ("#fff4e5", "#e65100"),
           "not-verified": ("#f2f4f7", "#667085"), "": ("#ffffff", "#344054")}


@dataclass
class _Box:
    node: Node
    ref: bool  # drawn as a reference to an element developed on another page
    x: float = 0.0
    y: float = 0.0
    w: float = 0.0
    h: float = 0.0
    lines: tuple[str, ...] = ()


def _lines(node: Node, ref: bool, width: float) -> tuple[str, ...]:
    if ref:
        return (f"{node.id} (see its page)",)
    inset = 40 if node.kind in ("Justification", "Assumption") else 0  # the text inside an ellipse
    chars = int((width - 2 * PAD - inset) / (FONT * 0.56))
    wrapped = textwrap.wrap(node.text, chars) or [""]
    if len(wrapped) > MAX_LINES:
        rest = textwrap.shorten(" ".join(wrapped[MAX_LINES - 1:]), chars, placeholder="...")
        wrapped = [*wrapped[:MAX_LINES - 1], rest]
    return (node.id, *wrapped)


def primary_parents(nodes: Mapping[str, Node]) -> dict[str, str]:
    """Each element's home: the strategy that lists it, else its first parent. It is developed there only."""
    home: dict[str, str] = {}
    for n in nodes.values():
        for ref in (*n.in_context_of, *n.supported_by):
            if ref not in home or (n.kind == "Strategy" and nodes.get(home[ref], n).kind != "Strategy"):
                home[ref] = n.id
    return home


def _layout(nodes: Mapping[str, Node], root: str, home: Mapping[str, str], expand_root_only: bool
            ) -> tuple[list[_Box], list[tuple[_Box, _Box, bool]], float, float]:
    """Place the tree under ``root``: columns by depth, leaves stacked, a parent centred on its children."""
    boxes: list[_Box] = []
    edges: list[tuple[_Box, _Box, bool]] = []
    x_of: dict[int, float] = {}
    cursor = [0.0]

    def place(nid: str, depth: int, parent: str | None) -> _Box:
        node = nodes[nid]
        ref = parent is not None and home.get(nid) != parent
        expand = not ref and not (expand_root_only and parent is not None)
        w = WIDTH.get(node.kind, 240) if not ref else 150
        box = _Box(node, ref, w=w)
        box.lines = _lines(node, ref, w)
        box.h = len(box.lines) * LINE + 2 * PAD + (16 if node.kind in ("Justification", "Assumption") else 0)
        x_of.setdefault(depth, 0.0)
        boxes.append(box)
        kids = [(c, True) for c in node.in_context_of] + [(c, False) for c in node.supported_by] if expand else []
        kids = [(c, ctx) for c, ctx in kids if c in nodes]
        if not kids:
            box.y = cursor[0]
            cursor[0] += box.h + GAP_Y
        else:
            placed = [(place(c, depth + 1, nid), ctx) for c, ctx in kids]
            top, bottom = placed[0][0].y, placed[-1][0].y + placed[-1][0].h
            box.y = max((top + bottom - box.h) / 2, top if box.h > bottom - top else top)
            edges.extend((box, child, ctx) for child, ctx in placed)
            cursor[0] = max(cursor[0], box.y + box.h + GAP_Y)
        box.x = depth  # column index for now
        return box

    place(root, 0, None)
    widths: dict[int, float] = {}
    for b in boxes:
        widths[int(b.x)] = max(widths.get(int(b.x), 0), b.w)
    xs, acc = {}, 10.0
    for col in sorted(widths):
        xs[col], acc = acc, acc + widths[col] + GAP_X
    for b in boxes:
        b.x = xs[int(b.x)]
        b.y += 10
    return boxes, edges, acc - GAP_X + 20, cursor[0] + 20


def _shape(b: _Box) -> str:
    fill, stroke = COLOURS.get(b.node.cls, COLOURS[""])
    dash = ' stroke-dasharray="4 3"' if b.ref else ""
    style = f'fill="{fill}" stroke="{stroke}" stroke-width="1.4"{dash}'
    x, y, w, h, k = b.x, b.y, b.w, b.h, b.node.kind
    if k == "Strategy":
        s = 10
        return f'<polygon points="{x + s},{y} {x + w},{y} {x + w - s},{y + h} {x},{y + h}" {style}/>'
    if k in ("Justification", "Assumption"):
        return (f'<ellipse cx="{x + w / 2}" cy="{y + h / 2}" rx="{w / 2}" ry="{h / 2}" {style}/>'
                f'<text x="{x + w - 10}" y="{y + h}" font-size="{FONT}" font-weight="bold">{k[0]}</text>')
    radius = {"Solution": 14, "Context": 8}.get(k, 0)
    out = f'<rect x="{x}" y="{y}" width="{w}" height="{h}" rx="{radius}" {style}/>'
    if b.node.undeveloped and not b.ref:
        cx, cy, d = x + w, y + h / 2, 6  # the undeveloped diamond, where its support would start
        out += f'<polygon points="{cx},{cy} {cx + d},{cy - d} {cx + 2 * d},{cy} {cx + d},{cy + d}" fill="#fff" ' \
               f'stroke="{stroke}" stroke-width="1.2"/>'
    return out


def _text(b: _Box) -> str:
    x = b.x + PAD + {"Justification": 20, "Assumption": 20, "Strategy": 6}.get(b.node.kind, 0)
    top = b.y + (8 if b.node.kind in ("Justification", "Assumption") else 0)
    rows = []
    for i, line in enumerate(b.lines):
        weight = ' font-weight="bold"' if i == 0 else ""
        y = top + PAD + (i + 0.8) * LINE
        rows.append(f'<text x="{x}" y="{y}" font-size="{FONT}"{weight}>{escape(line)}</text>')
    return "".join(rows)


def _edge(a: _Box, b: _Box, ctx: bool, page: str) -> str:
    x1, y1, x2, y2 = a.x + a.w, a.y + a.h / 2, b.x, b.y + b.h / 2
    mid = (x1 + x2) / 2
    marker, dash = ("ctx", ' stroke-dasharray="3 2"') if ctx else ("sup", "")
    return (f'<path d="M{x1},{y1} C{mid},{y1} {mid},{y2} {x2 - 2},{y2}" fill="none" stroke="#667085" '
            f'stroke-width="1"{dash} marker-end="url(#{marker}{page})"/>')


_Layout = tuple[list[_Box], list[tuple[_Box, _Box, bool]], float, float]


def _node(b: _Box, links: Mapping[str, str] | None, anchored: set[str]) -> str:
    """One box with its text; inline (``links`` given): the element's anchor where it is developed, its full text
    as a tooltip, and a link (a reference box: to where the element is developed; else: to its requirement, hazard
    or evidence in the report)."""
    drawn = _shape(b) + _text(b)
    if links is None:
        return drawn
    attrs = ""
    if not b.ref and b.node.id not in anchored:
        anchored.add(b.node.id)
        attrs = f' id="{escape(gsn_anchor(b.node.id), QUOTE)}"'
    title = f"<title>{escape(b.node.id + ': ' + b.node.text)}</title>"
    href = links.get(b.node.id, "")
    if href:
        return f'<a href="{escape(href, QUOTE)}"{attrs}>{title}{drawn}</a>'
    return f"<g{attrs}>{title}{drawn}</g>"


def _render(layout: _Layout, *, links: Mapping[str, str] | None = None, anchored: set[str] | None = None,
            page: str = "") -> str:
    boxes, edges, w, h = layout
    anchored = set() if anchored is None else anchored
    defs = (f'<defs><marker id="sup{page}" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" '
            'orient="auto"><path d="M0,0 L10,5 L0,10 z" fill="#344054"/></marker>'
            f'<marker id="ctx{page}" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" '
            'orient="auto"><path d="M0,0 L10,5 L0,10 z" fill="#fff" stroke="#344054"/></marker></defs>')
    body = "".join(_edge(a, b, c, page) for a, b, c in edges) + "".join(_node(b, links, anchored) for b in boxes)
    xmlns = "" if links is not None else ' xmlns="http://www.w3.org/2000/svg"'  # inline in HTML: none needed
    return (f'<svg{xmlns} width="{w:.0f}" height="{h:.0f}" viewBox="0 0 {w:.0f} {h:.0f}" '
            f'font-family="DejaVu Sans, Arial, sans-serif">{defs}{body}</svg>')


def page_svg(nodes: Mapping[str, Node], root: str, *, expand_root_only: bool = False) -> str:
    """One page of the argument as an SVG document: the tree under ``root``."""
    return _render(_layout(nodes, root, primary_parents(nodes), expand_root_only))


QUOTE = {'"': "&quot;"}


def gsn_anchor(nid: str) -> str:
    """The HTML id of an argument element where the report draws it developed."""
    return anchor("gsn", nid)


def argument_pages(nodes: Mapping[str, Node], top: str = "G-TOP", links: Mapping[str, str] | None = None
                   ) -> list[dict[str, Any]]:
    """The argument's figures: the top page, then one per strategy; each with a title, an SVG data URI and the SVG
    to put inline, whose elements link (``links``: element id -> the report's anchor of its requirement, hazard or
    evidence; an element drawn as a reference links to where it is developed) and carry their anchors."""
    from markupsafe import Markup

    def uri(svg: str) -> str:
        return "data:image/svg+xml;base64," + base64.b64encode(svg.encode("utf-8")).decode("ascii")

    home = primary_parents(nodes)
    roots = [(top, True)] + [(sid, False) for sid in nodes[top].supported_by if sid in nodes]
    layouts = {r: _layout(nodes, r, home, only) for r, only in roots}
    targets = {b.node.id: f"#{gsn_anchor(b.node.id)}" for r, _ in roots for b in layouts[r][0] if not b.ref}
    inline_links = {**(links or {}), **{nid: href for nid, href in targets.items() if nid not in (links or {})}}
    drawn: set[str] = set()  # an element's anchor where first drawn: a strategy's page before the top page
    pages = []
    for n, (r, _) in enumerate([*roots[1:], roots[0]]):
        svg = _render(layouts[r], links=_with_refs(layouts[r], inline_links, targets), anchored=drawn, page=f"-{n}")
        title = f"{top}: the top goal, its context and strategies" if r == top else f"{r}: {nodes[r].text}"
        pages.append({"title": title, "id": r, "anchor": f"argument-{r}", "uri": uri(_render(layouts[r])),
                      "svg": Markup(svg)})
    return [pages[-1], *pages[:-1]]


def _with_refs(layout: _Layout, links: Mapping[str, str], targets: Mapping[str, str]) -> dict[str, str]:
    """``links`` with each reference box of the page sent to where its element is developed."""
    out = dict(links)
    out.update({b.node.id: targets[b.node.id] for b in layout[0] if b.ref and b.node.id in targets})
    return out
