"""What the report's shell (``evidence_templates/report.html.j2``) puts in the page besides the templates' markup,
and the last pass over it: the filter script (plain JavaScript, a few lines, nothing fetched), a
Content-Security-Policy that lets the browser run that script only (by its hash) and fetch nothing, and
:func:`link_ids`, which makes every requirement id in the text a link to the requirement's anchor. The page stays
readable without JavaScript."""

from __future__ import annotations

import base64
import hashlib
import html
import re
from collections.abc import Iterable

SCRIPT = """
(function () {
  "use strict";
  var ids = {};
  document.querySelectorAll("[data-ids]").forEach(function (row) {
    row.getAttribute("data-ids").split(" ").forEach(function (id) { if (id) { ids[id.toLowerCase()] = true; } });
  });
  function matches(row, words, state) {
    var own = " " + (row.getAttribute("data-ids") || "").toLowerCase() + " ";
    var text = row.textContent.toLowerCase();
    if (state && row.getAttribute("data-state") !== state) { return false; }
    return words.every(function (w) { return ids[w] ? own.indexOf(" " + w + " ") !== -1 : text.indexOf(w) !== -1; });
  }
  document.querySelectorAll("table[data-filter]").forEach(function (table) {
    var rows = Array.prototype.slice.call(table.tBodies[0].rows);
    var box = document.createElement("div");
    var input = document.createElement("input");
    var select = document.createElement("select");
    var count = document.createElement("span");
    box.className = "filter";
    input.type = "search";
    input.placeholder = table.getAttribute("data-filter");
    input.setAttribute("aria-label", input.placeholder);
    ["any state", "verified", "failed", "not verified"].forEach(function (s, i) {
      var o = document.createElement("option");
      o.value = i ? s.replace(" ", "-") : "";
      o.textContent = s;
      select.appendChild(o);
    });
    count.className = "count";
    function apply() {
      var words = input.value.toLowerCase().split(/\\s+/).filter(Boolean), shown = 0;
      rows.forEach(function (row) {
        var ok = matches(row, words, select.value);
        row.hidden = !ok;
        shown += ok ? 1 : 0;
      });
      count.textContent = shown + " of " + rows.length + " shown";
    }
    input.addEventListener("input", apply);
    select.addEventListener("change", apply);
    box.append(input, " ", select, " ", count);
    table.parentNode.insertBefore(box, table);
    apply();
  });
})();
"""
"""The report's only script: a filter box (words and a state) over every table marked ``data-filter``; a word that
is a requirement id keeps the rows of that requirement (``data-ids``), any other word the rows whose text holds it."""

CSP = ("default-src 'none'; img-src data:; style-src 'unsafe-inline'; script-src '{hash}'; base-uri 'none'; "
       "form-action 'none'")


def script_hash(script: str = SCRIPT) -> str:
    """The CSP source of ``script``: ``sha256-`` and its base64 digest."""
    return "sha256-" + base64.b64encode(hashlib.sha256(script.encode("utf-8")).digest()).decode("ascii")


_SKIP = re.compile(r"<(script|style|svg|textarea|title|pre)\b.*?</\1\s*>", re.IGNORECASE | re.DOTALL)
_TAG = re.compile(r"<[^>]*>")


def link_ids(markup: str, ids: Iterable[str], anchor: dict[str, str]) -> str:
    """``markup`` with each id of ``ids`` in its text (outside links, tags, scripts, styles, SVG and preformatted
    text) made a link to ``#anchor[id]``; ids without an element of that anchor in ``markup`` stay text."""
    present = [i for i in ids if f'id="{anchor[i]}"' in markup]
    if not present:
        return markup
    words = re.compile(r"(?<![\w-])(" + "|".join(re.escape(html.escape(i)) for i in
                                                sorted(present, key=len, reverse=True)) + r")(?![\w-])")
    by_text = {html.escape(i): i for i in present}
    out, pos, depth = [], 0, 0
    for m in re.finditer(f"{_SKIP.pattern}|{_TAG.pattern}", markup, re.IGNORECASE | re.DOTALL):
        text = markup[pos:m.start()]
        out.append(text if depth else words.sub(
            lambda w: f'<a class="rid" href="#{html.escape(anchor[by_text[w.group(1)]])}">{w.group(1)}</a>', text))
        tag = m.group(0)
        if re.match(r"<a\b", tag, re.IGNORECASE):
            depth += 1
        elif re.match(r"</a\s*>", tag, re.IGNORECASE):
            depth = max(0, depth - 1)
        out.append(tag)
        pos = m.end()
    rest = markup[pos:]
    out.append(rest if depth else words.sub(
        lambda w: f'<a class="rid" href="#{html.escape(anchor[by_text[w.group(1)]])}">{w.group(1)}</a>', rest))
    return "".join(out)
