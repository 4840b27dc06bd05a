"""Fault-injection cases of the auditor's trust boundary (rows ``T1``..``T4``): what an applicant supplies (here, the
report templates) never executes, never reads the auditor's files and cannot contradict the gate. Rows ``T5``..``T17``
and ``T21`` (``assurance.fault_injection.trust``: the applicant's files, templates too, read bounded and checked
before work) follow.

Each case writes a template folder an applicant could name (``--templates`` or ``[report] templates``) and returns
the ``uav-el evidence`` command on the workspace's run that must refuse it (exit 2, one line naming the problem).
"""

from __future__ import annotations

from pathlib import Path

from assurance.fault_injection.basis_cases import BASIS_CASES
from assurance.fault_injection.case import Case
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


def _file_attachment(ws: Path) -> list[str]:
    """A template attaching a local file (here the applicant's own stand-in for a signing key) to the PDF."""
    secret = ws / "stand-in-signing-key.pem"
    secret.write_text("-----BEGIN PRIVATE KEY-----\nnot a key\n-----END PRIVATE KEY-----\n", "utf-8")
    body = f'<link rel="attachment" href="file://{secret}">'
    return _evidence(ws, "attach", _templates(ws, "attach", body))


def _claims_passed(ws: Path) -> list[str]:
    """A template printing 'Gate: PASSED' on a run whose gate fails."""
    return _evidence(ws, "claim", _templates(ws, "claim", "<h1>Gate: PASSED</h1>"), "--no-pdf")


def _network_fetch(ws: Path) -> list[str]:
    """A template whose stylesheet the PDF renderer would fetch from the network."""
    body = '<link rel="stylesheet" href="http://127.0.0.1:9/report.css">'
    return _evidence(ws, "fetch", _templates(ws, "fetch", body))


def pdf_renderer() -> bool:
    """Whether WeasyPrint loads here: without it no PDF is rendered, so nothing is fetched and the cases about
    what the PDF renderer reads (T2, T4) have nothing to show."""
    try:
        import weasyprint  # noqa: F401  (the optional ``pdf`` extra)
    except Exception:  # ImportError, or OSError when the Pango library is missing
        return False
    return True


PDF_CASES = ("T2-template-file-attachment", "T4-template-network-fetch")
_ALL: tuple[Case, ...] = (
    Case("T1-template-sandbox-escape", "a report template calling os.system through cycler.__init__.__globals__",
         _sandbox_escape, 2, "report template refused"),
    Case("T2-template-file-attachment", "a report template attaching file:///... (a key file) to the PDF",
         _file_attachment, 2, "which it refuses"),
    Case("T3-template-claims-passed", "a report template printing 'Gate: PASSED' on a failed gate", _claims_passed, 2,
         "gate verdict the gate did not give"),
    Case("T4-template-network-fetch", "a report template whose stylesheet is fetched from http://127.0.0.1:9",
         _network_fetch, 2, "which it refuses"),
)
APPLICANT_CASES: tuple[Case, ...] = (*(c for c in _ALL if c.id not in PDF_CASES or pdf_renderer()), *TRUST_CASES,
                                     *BASIS_CASES)
