"""Rendering and writing the evidence report: Jinja2 HTML, the PDF/A-3b with its attachments, CSV and text files."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from assurance import bounded as limits
from assurance.evidence.linking import CSP, SCRIPT, link_ids, script_hash
from assurance.evidence.navigation import req_anchor
from assurance.evidence.outline import SECTIONS, outline
from assurance.evidence.sanitise import bounded_clean
from assurance.files import atomic_write_bytes
from el.base.userfiles import UserFileError, read_text

ROOT = Path(__file__).resolve().parents[2]
"""The project root (paths under it are written relative to it)."""

TEMPLATES_DIR = ROOT / "evidence_templates"
"""The packaged templates: the ``evidence_templates`` package beside ``assurance`` (package data of the wheel, in
site-packages; the checkout's top-level folder when editable). Found by this file's place, never by a search of
``sys.path``, so that a folder of that name in the working directory is never taken for the packaged cover."""
TEMPLATE = "report.html.j2"
PDF_HINT = ("install WeasyPrint with the toolkit's pdf extra (`pip install 'uav-el-assurance[pdf]'`; in a source "
            "checkout `pip install -e '.[pdf]'`) and the Pango library it needs (Debian/Ubuntu: "
            "`apt-get install libpango-1.0-0 libpangoft2-1.0-0`)")


FAULTS_CSV = "faults.csv"


def faults_table(out: Path, warnings: list[str]) -> list[dict[str, str]] | None:
    """The fault-injection table (``uav-el fault-table``) found next to the report, for its appendix."""
    from assurance.fault_injection.table import read_table  # deferred: WeasyPrint, onnxruntime, off verify/land paths

    path = out / FAULTS_CSV
    if not path.is_file():
        return None
    try:
        return read_table(path)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        warnings.append(f"{path}: fault-injection table not shown: {exc}")
        return None


def fault_case_count() -> int:
    """How many fault-injection cases this toolkit replays (``uav-el fault-table`` without ``--quick``): the
    appendix says when the table next to the report holds fewer (a slice, ``make demo``)."""
    from assurance.fault_injection.table import CASES  # deferred: WeasyPrint, onnxruntime, off verify/land paths

    return len(CASES)


COVER = "cover.html.j2"
"""The first page (gate verdict, summary): always the packaged file, included by the packaged shell."""


def environment(templates: str | Path | None = None) -> Any:
    """The Jinja2 environment of the report: the immutable sandbox (a template reaches no Python internals and
    changes nothing), autoescape on, strict undefined. With a supplied template folder, its files come first and
    the packaged templates fill the gaps (a supplied section may import the packaged macros); every template is
    read through the bounded reader (:func:`bounded_loader`)."""
    from jinja2 import StrictUndefined
    from jinja2.sandbox import ImmutableSandboxedEnvironment

    folder = _supplied_folder(templates)
    return ImmutableSandboxedEnvironment(loader=bounded_loader([folder] if folder else [], TEMPLATES_DIR),
                                         autoescape=True, undefined=StrictUndefined, trim_blocks=True,
                                         lstrip_blocks=True, keep_trailing_newline=True)


MAX_TEMPLATE_BYTES = 1 << 20
"""A report template (or its stylesheet): a page of markup, not data (the packaged report is 14 KB)."""


def bounded_loader(supplied: Sequence[Path], packaged: Path = TEMPLATES_DIR) -> Any:
    """A Jinja2 loader of the templates in the ``supplied`` folders, then the ``packaged`` one (the first folder
    holding a name wins). A supplied folder is the applicant's: each file of it is read through ``el.base.userfiles``,
    confined to its folder (a symbolic link out of it, a FIFO, a device, a folder or a file over
    :data:`MAX_TEMPLATE_BYTES` is refused, ``UserFileError`` naming it, before a read that could block, never end
    or disclose the auditor's files), and recorded in ``.reads`` (relative path -> SHA-256)."""
    import hashlib
    import os

    from jinja2 import BaseLoader, TemplateNotFound
    from jinja2.loaders import split_template_path

    class BoundedLoader(BaseLoader):
        reads: dict[str, str]

        def get_source(self, environment: Any, template: str) -> tuple[str, str, Any]:
            pieces = split_template_path(template)  # refuses ".." (no way out of the folders)
            for folder in (*supplied, packaged):
                path = folder.joinpath(*pieces)
                if os.path.lexists(path):  # whatever is there (a FIFO too) is judged by the reader, not skipped
                    break
            else:
                raise TemplateNotFound(template)
            own = folder != packaged
            text = read_text(path, what="report template", max_bytes=MAX_TEMPLATE_BYTES,
                             **({"within": folder} if own else {}))
            if own:
                self.reads["/".join(pieces)] = hashlib.sha256(text.encode("utf-8")).hexdigest()
            mtime = _mtime_ns(path)
            return text, os.path.normpath(path), lambda: _mtime_ns(path) == mtime

    loader = BoundedLoader()
    loader.reads = {}
    return loader


def _mtime_ns(path: Path) -> int | None:
    """The modification time of ``path`` (None when it is gone): whether a loaded template is up to date."""
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


class TemplateError(ValueError):
    """A report template that cannot be read, compiled or rendered; the message names the file and the line."""


def _template_line(exc: BaseException) -> tuple[str, int | None]:
    """The template file and line where a rendering error arose (Jinja2 puts template frames in the traceback)."""
    where: tuple[str, int | None] = ("a report template", None)
    tb = exc.__traceback__
    while tb is not None:
        name = tb.tb_frame.f_code.co_filename
        if name.endswith((".j2", ".css", ".html")):
            where = (name, tb.tb_lineno)
        tb = tb.tb_next
    return where


def _render(env: Any, name: str, context: Mapping[str, Any]) -> str:
    """One template rendered; TemplateError naming the file and line of a broken or unsafe template."""
    from jinja2 import TemplateError as JinjaError
    from jinja2 import TemplateSyntaxError
    from jinja2.exceptions import SecurityError

    try:
        return env.get_template(name).render(**context)
    except UserFileError as exc:  # a supplied template that is no regular file, or too big: never read
        raise TemplateError(str(exc)) from None
    except TemplateSyntaxError as exc:
        raise TemplateError(f"{exc.filename or exc.name}:{exc.lineno}: report template does not compile: "
                            f"{exc.message}") from None
    except SecurityError as exc:
        where, line = _template_line(exc)
        raise TemplateError(f"{where}:{line if line is not None else '?'}: report template refused: it reaches "
                            f"outside what a template may use ({exc})") from None
    except (MemoryError, RecursionError):  # the bounded child names the limit
        raise
    except (JinjaError, ArithmeticError, LookupError, TypeError, ValueError, AttributeError, RuntimeError) as exc:
        where, line = _template_line(exc)  # {{ 1 // 0 }}, a missing key, a bad filter argument: the file's fault
        raise TemplateError(f"{where}:{line if line is not None else '?'}: report template fails to render: "
                            f"{type(exc).__name__}: {exc}") from None


SHELL_FILES = (TEMPLATE, COVER)
"""The packaged files of the report's shell (page, head and first page): a template folder's file of one of these
names, or any stylesheet there, is never used (the report says so)."""


def _supplied_folder(templates: str | Path | None) -> Path | None:
    """The applicant's template folder, None for the packaged templates."""
    if not templates:
        return None
    folder = Path(str(templates))
    return None if folder.resolve() == TEMPLATES_DIR.resolve() else folder


def _unused_files(folder: Path) -> list[str]:
    """The shell files and stylesheets of a supplied folder (never used), by name."""
    import os

    names = [n for n in SHELL_FILES if os.path.lexists(folder / n)]
    try:
        names += sorted(e.name for e in os.scandir(folder) if e.name.lower().endswith(".css"))[:20]
    except OSError:
        pass
    return names


def _render_supplied(folder: Path, name: str, context: Mapping[str, Any], seconds: float | None,
                     own_ids: Sequence[str]) -> tuple[str, dict[str, str]]:
    """One supplied template rendered and cleaned in a bounded child (:mod:`assurance.bounded`;
    :func:`assurance.evidence.sanitise.bounded_clean`, ``own_ids`` its sections' anchors): its clean markup and
    the files it read (path relative to the folder -> SHA-256)."""
    def work() -> tuple[str, dict[str, str]]:
        env = environment(folder)
        try:
            html = _render(env, name, context)
        except MemoryError:
            raise TemplateError(f"{folder / name}: report template refused: it needs more than the memory "
                                "limit") from None
        except RecursionError:
            raise TemplateError(f"{folder / name}: report template refused: it recurses without end (a template "
                                "including itself?)") from None
        try:  # cleaned here, under the same limits: the parent only places markup that is small, shallow and clean
            clean = bounded_clean(html, own_ids, where=str(folder / name), max_chars=MAX_SECTION_CHARS)
        except ValueError as exc:  # a bound exceeded: the message names the template and the limit
            raise TemplateError(str(exc)) from None
        return clean, dict(env.loader.reads)

    try:
        return limits.run_bounded(work, what=f"{folder / name}: report template", seconds=seconds or limits.SECONDS,
                                  memory_bytes=limits.MEMORY_BYTES)
    except limits.BoundedRenderError as exc:
        raise TemplateError(str(exc)) from None


MAX_SECTION_CHARS = 1 << 20
"""A supplied section's rendered markup: a section of an evidence report is kilobytes of text (1 MiB holds a
few small images inline; 48 MB of markup took the parent's sanitiser and PDF layout 400 s and 3.3 GB)."""


def _folder_digest(reads: Mapping[str, str]) -> str:
    """SHA-256 over the supplied files the report read (relative path and content hash, sorted)."""
    import hashlib

    h = hashlib.sha256()
    for rel_path, digest in sorted(reads.items()):
        h.update(f"{rel_path}:{digest}\n".encode())
    return h.hexdigest()


def render_report(context: Mapping[str, Any], templates: str | Path | None = None, *, seconds: float | None = None
                  ) -> tuple[str, dict[str, Any] | None]:
    """The report's HTML from its finished context, and what a supplied template folder contributed (None: the
    packaged templates only). The shell (doctype, head, Content-Security-Policy, stylesheet, first page, table of
    contents, section order, script) is the packaged ``report.html.j2``, rendered by the toolkit; a supplied folder
    replaces section templates only (``outline.SECTIONS``), each rendered in a bounded child and cleaned as an HTML
    fragment in that child (:func:`assurance.evidence.sanitise.bounded_clean`: size, element and depth caps)
    before it is put in the page (``seconds``: the wall-time limit of each, default ``bounded.SECONDS``).
    TemplateError
    naming the file (and line) of a broken, unsafe, endless or oversized template."""
    import os

    from markupsafe import Markup

    context = {**outline(context), **context}  # the sections of the registry, unless the caller lists its own
    folder = _supplied_folder(templates)
    shown = {s["id"] for s in context["sections"]}
    supplied: dict[str, str] = {}
    reads: dict[str, str] = {}
    if folder is not None:
        for name in context["section_templates"]:
            if name in SHELL_FILES or not os.path.lexists(folder / name):
                continue
            own = sorted(s.id for s in SECTIONS if s.template == name and s.id in shown)
            supplied[name], read = _render_supplied(folder, name, context, seconds, own)
            reads.update(read)
    about = None
    if folder is not None:
        about = {"folder": str(folder), "sha256": _folder_digest(reads), "files": sorted(reads),
                 "sections": sorted(supplied), "unused": _unused_files(folder)}
    context = {**context, "supplied_templates": about}
    env = environment(None)
    parts = [{"template": name, "supplied": name in supplied,
              "html": Markup(supplied[name]) if name in supplied else Markup(_render(env, name, context))}
             for name in context["section_templates"]]
    shell = {"csp": Markup(CSP.format(hash=script_hash())), "script": Markup(SCRIPT), "parts": parts}
    html = _render(env, TEMPLATE, {**context, "shell": shell})
    ids = [str(r["id"]) for r in context.get("requirements") or []]
    return link_ids(html, ids, {i: req_anchor(i) for i in ids}), about


def render_html(context: Mapping[str, Any], templates: str | Path | None = None) -> str:
    """The report's HTML (:func:`render_report`, without what the supplied folder contributed)."""
    return render_report(context, templates)[0]


def rel(path: str | Path | None) -> str | None:
    """A path relative to the project root when it lies under it (as written elsewhere otherwise)."""
    if path is None:
        return None
    p = Path(path)
    try:
        return p.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


PDF_VARIANT = "pdf/a-3b"


class RefusedResourceError(TemplateError):
    """The report asked the PDF renderer for a resource it may not read (a local file, the network)."""


def _fetcher(served: Sequence[Path]) -> Any:
    """WeasyPrint's URL fetcher for the report: ``data:`` URIs and the files in ``served`` (the report's own
    generated files), nothing else (no ``file:`` outside them, no network, no other scheme). Every refused URL
    is recorded in ``.refused``."""
    from urllib.parse import unquote, urlsplit

    from weasyprint.urls import URLFetcher

    allowed = {a.resolve() for a in served}

    class ReportFetcher(URLFetcher):
        refused: list[str]

        def fetch(self, url: str, headers: Any = None) -> Any:
            scheme = url.split(":", 1)[0].lower() if ":" in url else ""
            if scheme == "data":
                return super().fetch(url, headers)
            if scheme == "file":
                parts = urlsplit(url)
                if not parts.netloc and Path(unquote(parts.path)).resolve() in allowed:
                    return super().fetch(url, headers)
            self.refused.append(url)
            raise ValueError(f"the report's PDF reads only data: URIs and its own files, not {url}")

    fetcher = ReportFetcher(allowed_protocols=("data", "file"), allow_redirects=False)
    fetcher.refused = []
    return fetcher


PDF_SECONDS = 300.0
"""Wall-time limit of the PDF layout of a report holding supplied sections (in a bounded child, with
``bounded.MEMORY_BYTES`` more memory): the packaged release report lays out in about a minute on 2 cores."""


def write_pdf(html: str, path: Path, attachments: Sequence[Path] = (), served: Sequence[Path] = (),
              bounded: str | None = None) -> str | None:
    """Write the PDF/A-3b of ``html`` (WeasyPrint) with ``attachments`` embedded; returns None, or why no
    PDF was written. The renderer reads nothing but ``data:`` URIs and the ``served`` files:
    RefusedResourceError (no PDF) naming the first URL the HTML asked for beyond them. ``bounded``: the supplied
    template folder whose sections the page holds: the layout then runs in a bounded child
    (:data:`PDF_SECONDS`, ``bounded.MEMORY_BYTES``), and one that exceeds them is a TemplateError naming it."""
    try:
        with warnings.catch_warnings():  # e.g. "HarfBuzz-Subset will be required by future versions"
            warnings.simplefilter("ignore", DeprecationWarning)
            from weasyprint import HTML
    except Exception as exc:  # ImportError, or OSError when the Pango library is missing
        return f"PDF not written: WeasyPrint cannot be loaded ({type(exc).__name__}: {exc}); {PDF_HINT}"
    from weasyprint import Attachment

    tmp = path.with_name(f".{path.name}.tmp")

    def layout() -> list[str]:
        fetcher = _fetcher(served)
        files = [Attachment(filename=str(a), name=a.name, description=f"{a.name} of this evidence report",
                            relationship="Data" if a.suffix in (".json", ".csv", ".xml") else "Supplement")
                 for a in attachments if a.is_file()]
        HTML(string=html, base_url=str(path.parent), url_fetcher=fetcher).write_pdf(
            str(tmp), pdf_variant=PDF_VARIANT, attachments=files)
        return list(fetcher.refused)

    try:
        if bounded is None:
            refused = layout()
        else:
            try:
                refused = limits.run_bounded(layout, what=f"{bounded}: the PDF layout of its sections",
                                             seconds=PDF_SECONDS, memory_bytes=limits.MEMORY_BYTES)
            except limits.BoundedRenderError as exc:
                raise TemplateError(f"{exc}; report refused") from None
        if refused:
            tmp.unlink(missing_ok=True)
            more = f" (and {len(refused) - 1} more)" if len(refused) > 1 else ""
            raise RefusedResourceError(f"{path}: PDF not written: the report asks the renderer for "
                                       f"{refused[0]}{more}, which it refuses: a report reads only data: "
                                       "URIs and its own files")
        tmp.replace(path)
    except TemplateError:
        tmp.unlink(missing_ok=True)
        raise
    except Exception as exc:
        tmp.unlink(missing_ok=True)
        return f"PDF not written: WeasyPrint failed ({type(exc).__name__}: {exc})"
    return None


def pdf_attachment_names(path: str | Path) -> list[str]:
    """Names of the files embedded in a PDF (its EmbeddedFiles name tree), read by pypdf (the ``pdf`` extra)."""
    from pypdf import PdfReader

    return list(PdfReader(str(path)).attachments)


def write_csv_rows(path: Path, rows: Sequence[Mapping[str, str]], columns: Sequence[str]) -> None:
    """Write records as CSV (atomically)."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_text(path, buf.getvalue())


def write_text(path: Path, text: str) -> None:
    """Write UTF-8 text atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))
