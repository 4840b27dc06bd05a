"""Fault-injection cases of the auditor's trust boundary (row ``T1``, then the report's shell in
``assurance.fault_injection.report_cases``): what an applicant supplies (here, the report templates) never executes,
never reads the auditor's files and cannot reach the first page. Rows ``T5``..``T17``
and ``T21`` (``assurance.fault_injection.trust``: the applicant's files, templates too, read bounded and checked
before work) follow.

Each case writes a template folder an applicant could name (``--templates`` or ``[report] templates``) and returns
the ``uav-el evidence`` command on the workspace's run that must refuse it (exit 2, one line naming the problem).
"""

from __future__ import annotations

from pathlib import Path

from assurance.fault_injection.basis_cases import BASIS_CASES
from assurance.fault_injection.case import Case
from assurance.fault_injection.report_cases import PDF_CASE_IDS, REPORT_CASES
from assurance.fault_injection.trust import TRUST_CASES


def _templates(ws: Path, name: str, body: str) -> Path:
    folder = ws / f"templates-{name}"
    folder.mkdir(exist_ok=True)
    (folder / "auditor_issre.html.j2").write_text(f"<section>\n<p>issre</p>\n{body}\n</section>\n", "utf-8")
    return folder


def _evidence(ws: Path, name: str, folder: Path, *extra: str) -> list[str]:
    return ["evidence", "--run", str(ws / "run"), "--out", str(ws / f"rep-{name}"), "--boot", "20",
            "--templates", str(folder), *extra]


def _sandbox_escape(ws: Path) -> list[str]:
    """A template reaching the os module through a global's __init__.__globals__ to run a shell command."""
    marker = ws / "T1-executed"
    body = "{{ cycler.__init__.__globals__.os.system('touch " + str(marker) + "') }}"
    return _evidence(ws, "sandbox", _templates(ws, "sandbox", body), "--no-pdf")


def pdf_renderer() -> bool:
    """Whether WeasyPrint loads here: without it no PDF is rendered, so nothing is fetched and the cases about
    what the PDF renderer reads (T2, T4) have nothing to show."""
    try:
        import weasyprint  # noqa: F401  (the optional ``pdf`` extra)
    except Exception:  # ImportError, or OSError when the Pango library is missing
        return False
    return True


_ALL: tuple[Case, ...] = (
    Case("T1-template-sandbox-escape", "a report template calling os.system through cycler.__init__.__globals__",
         _sandbox_escape, 2, "report template refused"),
    *REPORT_CASES,
)
APPLICANT_CASES: tuple[Case, ...] = (*(c for c in _ALL if c.id not in PDF_CASE_IDS or pdf_renderer()), *TRUST_CASES,
                                     *BASIS_CASES)
