"""Rendering and writing the evidence report: Jinja2 HTML, the PDF/A-3b with its attachments, CSV and text files."""

from __future__ import annotations

import re
import warnings
from collections import Counter
from collections.abc import Mapping, Sequence
from html import unescape as html_unescape
from pathlib import Path
from typing import Any

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
    from assurance.fault_injection.table import read_table

    path = out / FAULTS_CSV
    if not path.is_file():
        return None
    try:
        return read_table(path)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        warnings.append(f"{path}: fault-injection table not shown: {exc}")
        return None


COVER = "cover.html.j2"
"""The first page (gate verdict, summary): always the packaged file, never a template folder's."""


def environment(templates: str | Path | None = None) -> Any:
    """The Jinja2 environment of the report: the immutable sandbox (a template reaches no Python internals and
    changes nothing), autoescape on, strict undefined. A user's template folder overrides the packaged templates
    file by file (the packaged ones fill the gaps); every template is read through the bounded reader
    (:func:`bounded_loader`)."""
    from jinja2 import StrictUndefined
    from jinja2.sandbox import ImmutableSandboxedEnvironment

    folders = [Path(templates)] if templates and Path(templates) != TEMPLATES_DIR else []
    return ImmutableSandboxedEnvironment(loader=bounded_loader([*folders, TEMPLATES_DIR]), autoescape=True,
                                         undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                                         keep_trailing_newline=True)


MAX_TEMPLATE_BYTES = 1 << 20
"""A report template (or its stylesheet): a page of markup, not data (the packaged report is 14 KB)."""


def bounded_loader(folders: Sequence[Path]) -> Any:
    """A Jinja2 loader of the templates in ``folders`` (the first folder holding a name wins) that reads each
    through ``el.userfiles``: a template folder is the applicant's, so a name there that is a FIFO, a device (or a
    link to one), a folder or a file over :data:`MAX_TEMPLATE_BYTES` is refused (``UserFileError`` naming it)
    before a read that could block or never end, instead of being skipped for the packaged one (Jinja's own
    ``FileSystemLoader`` passes over what ``isfile`` denies, and reads what it takes with a plain ``open``)."""
    import os

    from jinja2 import BaseLoader, TemplateNotFound
    from jinja2.loaders import split_template_path

    from el.userfiles import read_text

    class BoundedLoader(BaseLoader):
        def get_source(self, environment: Any, template: str) -> tuple[str, str, Any]:
            pieces = split_template_path(template)  # refuses ".." (no way out of the folders)
            for folder in folders:
                path = folder.joinpath(*pieces)
                if os.path.lexists(path):  # whatever is there (a FIFO too) is judged by the reader, not skipped
                    break
            else:
                raise TemplateNotFound(template)
            text = read_text(path, what="report template", max_bytes=MAX_TEMPLATE_BYTES)
            mtime = _mtime_ns(path)
            return text, os.path.normpath(path), lambda: _mtime_ns(path) == mtime

    return BoundedLoader()


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

    from el.userfiles import UserFileError

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
    except (JinjaError, TypeError, ValueError, AttributeError, KeyError, OverflowError) as exc:
        where, line = _template_line(exc)
        raise TemplateError(f"{where}:{line if line is not None else '?'}: report template fails to render: "
                            f"{type(exc).__name__}: {exc}") from None


_BODY = re.compile(r"<body\b[^>]*>", re.IGNORECASE)
_TAG = re.compile(r"<[^>]*>")
_VERDICT = re.compile(r"\bgate\b\W{0,24}(passed|failed|waived|incomplete|pass|fail)\b", re.IGNORECASE)


def verdict_phrases(html: str, verdict: str) -> Counter[str]:
    """Phrases of ``html``'s text that state a gate verdict other than ``verdict`` ("Gate: PASSED" on a failed
    gate), with their counts."""
    text = " ".join(html_unescape(_TAG.sub(" ", html)).split())
    return Counter(m.group(0) for m in _VERDICT.finditer(text)
                   if not verdict.lower().startswith(m.group(1).lower()))


def render_html(context: Mapping[str, Any], templates: str | Path | None = None) -> str:
    """The report's HTML from its finished context: the body from the (possibly user-supplied) templates, and
    the first page (gate verdict, summary) from the packaged cover, put first in the body by the toolkit, which
    then links the requirement ids and adds its script (:func:`finish_html`).
    TemplateError naming the file and line of a broken or unsafe template, or naming what a supplied template
    says against the gate's verdict (beyond what the packaged templates quote from the evidence, such as the
    fault table's expected outputs). The sections and their order come from the section registry
    (``assurance.evidence.outline``)."""
    from assurance.evidence.outline import outline

    context = {**outline(context), **context}  # the sections of the registry, unless the caller lists its own
    supplied = bool(templates) and Path(str(templates)) != TEMPLATES_DIR
    body = _render(environment(templates), TEMPLATE, context)
    if supplied:
        verdict = str(context["gate"])
        said = verdict_phrases(body, verdict) - verdict_phrases(_render(environment(None), TEMPLATE, context), verdict)
        if said:
            raise TemplateError(f"{templates}: the supplied report templates state a gate verdict the gate did not "
                                f"give ({'; '.join(repr(s) for s in sorted(said))}; the gate is {verdict}): refused")
    opening = _BODY.search(body)
    if opening is None:
        where = Path(str(templates)) if supplied else TEMPLATES_DIR
        raise TemplateError(f"{where / TEMPLATE}: the report template has no <body> element to put the first page in")
    cover = _render(environment(None), COVER, context)
    return finish_html(body[:opening.end()] + "\n" + cover + body[opening.end():], context)


def finish_html(html: str, context: Mapping[str, Any]) -> str:
    """The toolkit's last pass (``assurance.evidence.linking``): every requirement id of the text a link to its
    anchor, the Content-Security-Policy, the filter script."""
    from assurance.evidence.linking import finish
    from assurance.evidence.navigation import req_anchor

    ids = [str(r["id"]) for r in context.get("requirements") or []]
    return finish(html, ids, {i: req_anchor(i) for i in ids})


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


def write_pdf(html: str, path: Path, attachments: Sequence[Path] = (), served: Sequence[Path] = ()) -> str | None:
    """Write the PDF/A-3b of ``html`` (WeasyPrint) with ``attachments`` embedded; returns None, or why no
    PDF was written. The renderer reads nothing but ``data:`` URIs and the ``served`` files:
    RefusedResourceError (no PDF) naming the first URL the HTML asked for beyond them."""
    try:
        with warnings.catch_warnings():  # e.g. "HarfBuzz-Subset will be required by future versions"
            warnings.simplefilter("ignore", DeprecationWarning)
            from weasyprint import HTML
    except Exception as exc:  # ImportError, or OSError when the Pango library is missing
        return f"PDF not written: WeasyPrint cannot be loaded ({type(exc).__name__}: {exc}); {PDF_HINT}"
    from weasyprint import Attachment

    tmp = path.with_name(f".{path.name}.tmp")
    fetcher = _fetcher(served)
    try:
        files = [Attachment(filename=str(a), name=a.name, description=f"{a.name} of this evidence report",
                            relationship="Data" if a.suffix in (".json", ".csv", ".xml") else "Supplement")
                 for a in attachments if a.is_file()]
        HTML(string=html, base_url=str(path.parent), url_fetcher=fetcher).write_pdf(
            str(tmp), pdf_variant=PDF_VARIANT, attachments=files)
        if fetcher.refused:
            tmp.unlink(missing_ok=True)
            more = f" (and {len(fetcher.refused) - 1} more)" if len(fetcher.refused) > 1 else ""
            raise RefusedResourceError(f"{path}: PDF not written: the report asks the renderer for "
                                       f"{fetcher.refused[0]}{more}, which it refuses: a report reads only data: "
                                       "URIs and its own files")
        tmp.replace(path)
    except RefusedResourceError:
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
    from assurance.files import atomic_write_bytes

    atomic_write_bytes(path, text.encode("utf-8"))
