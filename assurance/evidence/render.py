"""Rendering and writing the evidence report: Jinja2 HTML, the PDF/A-3b with its attachments, CSV and text files."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
"""The project root (paths under it are written relative to it)."""
TEMPLATES_DIR = Path(__file__).resolve().parents[1] / "templates"  # package data: found by an installed wheel too
TEMPLATE = "report.html.j2"
PDF_HINT = ("install WeasyPrint (`pip install weasyprint`, or `pip install -e '.[pdf]'`) and the Pango "
            "library it needs (Debian/Ubuntu: `apt-get install libpango-1.0-0 libpangoft2-1.0-0`)")


FAULTS_CSV = "faults.csv"


def faults_table(out: Path, warnings: list[str]) -> list[dict[str, str]] | None:
    """The fault-injection table (``uav-el fault-table``) found next to the report, for its appendix."""
    from assurance.campaign.fault_injection import read_table

    path = out / FAULTS_CSV
    if not path.is_file():
        return None
    try:
        return read_table(path)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        warnings.append(f"{path}: fault-injection table not shown: {exc}")
        return None


def environment(templates: str | Path | None = None) -> Any:
    """The Jinja2 environment of the report: autoescape on for every template, strict undefined. A user's
    template folder overrides the packaged templates file by file (the packaged ones fill the gaps)."""
    from jinja2 import ChoiceLoader, Environment, FileSystemLoader, StrictUndefined

    folders = [str(templates)] if templates and Path(templates) != TEMPLATES_DIR else []
    loader = ChoiceLoader([FileSystemLoader(f) for f in (*folders, str(TEMPLATES_DIR))])
    return Environment(loader=loader, autoescape=True,
                       undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)


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


def render_html(context: Mapping[str, Any], templates: str | Path | None = None) -> str:
    """The report's HTML from its finished context; TemplateError naming the file and line of a broken template."""
    from jinja2 import TemplateError as JinjaError
    from jinja2 import TemplateSyntaxError

    try:
        return environment(templates).get_template(TEMPLATE).render(**context)
    except TemplateSyntaxError as exc:
        raise TemplateError(f"{exc.filename or exc.name}:{exc.lineno}: report template does not compile: "
                            f"{exc.message}") from None
    except (JinjaError, TypeError, ValueError, AttributeError, KeyError) as exc:
        name, line = _template_line(exc)
        raise TemplateError(f"{name}:{line if line is not None else '?'}: report template fails to render: "
                            f"{type(exc).__name__}: {exc}") from None


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


def write_pdf(html: str, path: Path, attachments: Sequence[Path] = ()) -> str | None:
    """Write the PDF/A-3b of ``html`` (WeasyPrint) with ``attachments`` embedded; returns None, or why no
    PDF was written."""
    try:
        with warnings.catch_warnings():  # e.g. "HarfBuzz-Subset will be required by future versions"
            warnings.simplefilter("ignore", DeprecationWarning)
            from weasyprint import HTML
    except Exception as exc:  # ImportError, or OSError when the Pango library is missing
        return f"PDF not written: WeasyPrint cannot be loaded ({type(exc).__name__}: {exc}); {PDF_HINT}"
    from weasyprint import Attachment

    tmp = path.with_name(f".{path.name}.tmp")
    try:
        files = [Attachment(filename=str(a), name=a.name, description=f"{a.name} of this evidence report",
                            relationship="Data" if a.suffix in (".json", ".csv", ".xml") else "Supplement")
                 for a in attachments if a.is_file()]
        HTML(string=html, base_url=str(path.parent)).write_pdf(str(tmp), pdf_variant=PDF_VARIANT, attachments=files)
        tmp.replace(path)
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
