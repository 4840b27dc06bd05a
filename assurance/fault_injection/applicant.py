"""Fault-injection cases of the auditor's trust boundary, assembled: the report's shell against a hostile template
folder (rows ``T1``..``T4``, ``T25``..``T29``, ``T50``..``T54``: ``assurance.fault_injection.report_cases``), the
applicant's files read bounded and checked before work (``T5``..``T17``, ``T21``, ``T30``..``T39``:
``assurance.fault_injection.trust``), the certification basis and the pins (``T18``..``T24``, ``T40``..``T44``:
``assurance.fault_injection.basis_cases``), class names, categories and colours (``T70``..``T79``:
``assurance.fault_injection.name_cases``).
"""

from __future__ import annotations

from assurance.fault_injection.basis_cases import BASIS_CASES
from assurance.fault_injection.case import Case
from assurance.fault_injection.name_cases import NAME_CASES
from assurance.fault_injection.report_cases import PDF_CASE_IDS, REPORT_CASES
from assurance.fault_injection.trust import TRUST_CASES


def pdf_renderer() -> bool:
    """Whether WeasyPrint loads here: without it no PDF is rendered, so the cases whose check reads the PDF
    (``PDF_CASE_IDS``) have nothing to show."""
    try:
        import weasyprint  # noqa: F401  (the optional ``pdf`` extra)
    except Exception:  # ImportError, or OSError when the Pango library is missing
        return False
    return True


APPLICANT_CASES: tuple[Case, ...] = (*(c for c in REPORT_CASES if c.id not in PDF_CASE_IDS or pdf_renderer()),
                                     *TRUST_CASES, *BASIS_CASES, *NAME_CASES)
