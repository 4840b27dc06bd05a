"""The report's navigation records: an anchor for every requirement, hazard, test and artefact, the test list with
full messages and links to each test's source (file and line), and the files written beside the report; the
links both ways (hazard -> requirement -> tests -> result -> artefacts, and back) are built here as finished
records, so the templates only lay them out."""

from __future__ import annotations

import ast
import hashlib
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

from assurance import requirements as rq
from el.base.userfiles import UserFileError, read_text

_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")
_REPEATED = re.compile(r"(?<![\w-])([A-Za-z][^:\n]{1,59}: )(?:\1)+")
MAX_SUMMARY = 160
"""A test message longer than this (or of several lines) is shown by its first words; the full text on demand."""
MAX_SOURCE_BYTES = 2 << 20
"""A test source file read for its line numbers (a module of tests, not data)."""


def anchor(prefix: str, key: str) -> str:
    """An HTML id for ``key`` (``req-`` and a requirement id, ``haz-H1``): its safe characters, with a short hash
    when any were dropped, so two keys never share an id."""
    safe = _UNSAFE.sub("-", key).strip("-")
    if safe == key:
        return f"{prefix}-{safe}"
    return f"{prefix}-{safe[:60]}-{hashlib.sha256(key.encode('utf-8')).hexdigest()[:8]}"


def req_anchor(rid: str) -> str:
    """The anchor of a requirement: its row in the traceability matrix (tests, result, artefacts, hazards)."""
    return anchor("req", rid)


def clean_message(message: str) -> str:
    """A test or check message without a prefix said twice ("insufficient evidence: insufficient evidence: x")."""
    return _REPEATED.sub(r"\1", (message or "").strip())


def message_view(message: str) -> dict[str, Any]:
    """A message as the report shows it: the first words (cut at a word, never mid-word) and the full text, with
    whether they differ (then the full text is behind a ``<details>``)."""
    full = clean_message(message)
    first = full.splitlines()[0] if full else ""
    if len(first) > MAX_SUMMARY:
        first = first[:MAX_SUMMARY].rsplit(" ", 1)[0].rstrip(",;:") + " ..."
    return {"summary": first, "full": full, "long": first != full}


def status_summary(status: str, summary: str) -> str:
    """A check's status and summary in one line, the status said once."""
    summary = clean_message(summary)
    return summary if summary.lower().startswith(status.lower()) else f"{status}: {summary}"


def _function_lines(path: Path, cache: dict[Path, dict[str, int]]) -> dict[str, int]:
    """``name`` / ``Class::name`` -> line of each test function of a Python file (empty when unreadable)."""
    if path in cache:
        return cache[path]
    lines: dict[str, int] = {}
    try:
        tree = ast.parse(read_text(path, what="test source", max_bytes=MAX_SOURCE_BYTES))
    except (OSError, UserFileError, SyntaxError, ValueError, RecursionError):
        tree = None
    for node in tree.body if tree is not None else []:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            lines[node.name] = node.lineno
        elif isinstance(node, ast.ClassDef):
            lines[node.name] = node.lineno
            lines.update({f"{node.name}::{f.name}": f.lineno for f in node.body
                          if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)})
    cache[path] = lines
    return lines


def source_of(nodeid: str, rootdir: Path | None, out: Path, cache: dict[Path, dict[str, int]]
                ) -> dict[str, Any]:
    """Where a test is: its file (relative to the pytest root), the line of its function, and a link relative to
    the report's folder (``file#L<line>``); no link when the file is not found here."""
    file, _, rest = nodeid.partition("::")
    func = rest.split("[", 1)[0]
    path = Path(file) if Path(file).is_absolute() or rootdir is None else rootdir / file
    if not file.endswith(".py") or not path.is_file():
        return {"file": file, "line": None, "href": ""}
    line = _function_lines(path, cache).get(func)
    try:
        rel = Path(os.path.relpath(path.resolve(), out.resolve())).as_posix()
    except ValueError:  # another drive
        return {"file": file, "line": line, "href": ""}
    return {"file": file, "line": line, "href": quote(rel) + (f"#L{line}" if line else "")}


def short_name(nodeid: str) -> str:
    """A test's short name: its function and parameters, without the file."""
    return nodeid.split("::", 1)[1] if "::" in nodeid else nodeid


def tests_view(results: Mapping[str, Any], req_doc: Mapping[str, Any] | None, out: Path
               ) -> list[dict[str, Any]]:
    """Every claiming test once, in registry order: anchor, outcome, the requirements it claims, full message and
    a link to its source."""
    ctx = (req_doc or {}).get("context") or {}
    rootdir = Path(ctx["rootdir"]) if ctx.get("rootdir") else None
    cache: dict[Path, dict[str, int]] = {}
    tests: dict[str, dict[str, Any]] = {}
    for rid, res in results.items():
        for t in res.tests:
            if t.nodeid not in tests:
                tests[t.nodeid] = {"nodeid": t.nodeid, "name": short_name(t.nodeid), "anchor": anchor("test", t.nodeid),
                                   "outcome": t.outcome, "outcome_class": outcome_class(t.outcome),
                                   "requirements": [], "message": message_view(t.message),
                                   "source": source_of(t.nodeid, rootdir, out, cache)}
            tests[t.nodeid]["requirements"].append({"id": rid, "anchor": req_anchor(rid)})
    return list(tests.values())


def outcome_class(outcome: str) -> str:
    """The colour class of a test outcome."""
    return "verified" if outcome in rq.PASSING else "failed" if outcome in rq.FAILING else "not-verified"


def code_statement(req_doc: Mapping[str, Any] | None, current: str | None) -> str:
    """What code the test links show: the code the requirement results are bound to, and whether it is this."""
    ctx = (req_doc or {}).get("context") or {}
    code = ctx.get("code") or {}
    bound = code.get("sha256") or ctx.get("code_sha256")
    if not bound:
        return "No requirement results: no test ran."
    commit = f", git commit {code['git_commit']}" if code.get("git_commit") else ""
    version = f"version {code['version']}, " if code.get("version") else ""
    same = ("the code here is that code, so the links show the lines that ran" if current == bound else
            f"the code here differs (SHA-256 {str(current)[:12]}): a link may show other lines than ran")
    return (f"The tests ran on the toolkit's code {version}SHA-256 {bound[:16]}{commit} (pytest root "
            f"{ctx.get('rootdir') or 'not recorded'}); {same}. Links are relative to this report's folder.")


REPORT_FILES = (
    ("evidence.json", "identity, gate, requirement states, checks and results, for tools"),
    ("evidence.pdf", "this report as PDF/A-3b with the files below attached (when written)"),
    ("results.csv", "the results table"),
    ("traceability.csv", "one row per requirement and claiming test"),
    ("requirements.json", "the requirement results of the test session (uav-el verify)"),
    ("junit.xml", "the test session's JUnit XML"),
    ("argument.gsn.yaml", "the safety argument in gsn2x's YAML"),
    ("issre.csv", "the ISSRE 2022 monitor figures"),
    ("faults.csv", "the fault-injection table"),
    ("SHA256SUMS", "the SHA-256 of every file of the report"),
)
"""The files a report folder holds, in the order the report lists them."""
WRITTEN = {"evidence.json", "evidence.pdf", "traceability.csv", "argument.gsn.yaml", "issre.csv", "SHA256SUMS"}
"""Those the report writes (the others are its inputs, listed when present)."""


def files_view(out: Path, run: Path, run_label: str, csv_name: str, tests: Sequence[Mapping[str, Any]],
               used_by: Mapping[str, list[str]], pdf: bool = True) -> list[dict[str, Any]]:
    """The artefacts a requirement relies on, each with its anchor and a link: the files beside the report, the
    campaign run (``run_label``: its path as the report writes it) and the test files; ``used_by``: artefact key ->
    the requirements that rely on it."""
    rows = []
    for name, what in REPORT_FILES:
        name = csv_name if name == "results.csv" else name
        if (name not in WRITTEN and not (out / name).is_file()) or (name == "evidence.pdf" and not pdf):
            continue
        rows.append({"key": name, "anchor": anchor("art", name), "name": name, "href": quote(name), "what": what})
    try:
        run_href = quote(Path(os.path.relpath(run.resolve(), out.resolve())).as_posix()) + "/manifest.json"
    except ValueError:
        run_href = ""
    rows.append({"key": "run", "anchor": anchor("art", "run"), "name": f"campaign run {run_label}", "href": run_href,
                 "what": "the campaign's manifest, shards and signed statement"})
    seen = set()
    for t in tests:
        file = t["source"]["file"]
        if file not in seen:
            seen.add(file)
            href = t["source"]["href"].split("#", 1)[0]
            rows.append({"key": f"test:{file}", "anchor": anchor("art", f"test:{file}"), "name": file,
                         "href": href, "what": "requirement tests"})
    for r in rows:
        r["used_by"] = [{"id": rid, "anchor": req_anchor(rid)} for rid in used_by.get(r["key"], [])]
    return rows
