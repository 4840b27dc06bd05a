"""A hostile applicant's templates against the report as the auditor reads it: in a real browser (headless
Chromium: CSS applied, the page's script run) and on page 1 of the PDF, a failed gate reads FAILED on the first
page whatever the template folder holds (a stylesheet collapsing the cover and painting PASSED with generated
content, a shell template putting the cover in a comment or swallowing the CSP, a section with a script, a
refresh to the applicant's server and an unclosed comment)."""

from __future__ import annotations

import base64
import io
import json
from pathlib import Path

import pytest
from test_report_navigation import browser

from assurance import cli

HOSTILE = {
    "evidence.css": ".cover, #cover { max-height: 0 !important; overflow: hidden !important; }\n"
                    "body::before { content: '\\47 ate: PASSED'; font-size: 40pt; color: green; }\n",
    "report.html.j2": "<!DOCTYPE html><html><head data-x='><!-- <body> -->'><title>x</title></head>"
                      "<body><p>Gate: PASSED</p></body></html>\n",
    "cover.html.j2": "<header id='cover'><div class='gate verified'>Gate: PASSED</div></header>\n",
    "auditor_issre.html.j2": "<section id='issre'><h2>ISSRE</h2>"
                             "<script>document.querySelectorAll('.gate').forEach(function (g) {"
                             " g.textContent = 'Gate: PASSED'; });</script>"
                             "<meta http-equiv='refresh' content='0; url=http://127.0.0.1:9/?run=x'>"
                             "<style>.cover { display: none }</style>"
                             "<p class='gate verified'>Gate: PASSED</p><!-- unclosed\n</section>\n",
}


@pytest.fixture(scope="module")
def hostile_report(tiny_campaign, tmp_path_factory) -> Path:
    pytest.importorskip("weasyprint")
    root = tmp_path_factory.mktemp("hostile")
    folder = root / "applicant-templates"
    folder.mkdir()
    for name, text in HOSTILE.items():
        (folder / name).write_text(text, "utf-8")
    out = root / "report"
    code = cli.main(["evidence", "--run", str(tiny_campaign["run"]), "--out", str(out), "--boot", "50",
                     "--templates", str(folder)])
    assert code == 1
    assert json.loads((out / "evidence.json").read_text("utf-8"))["gate"]["result"] == "FAILED"
    return out


def _pdf_page_one(data: bytes) -> str:
    from pypdf import PdfReader

    return PdfReader(io.BytesIO(data)).pages[0].extract_text()


def test_page_one_of_the_pdf_says_failed(hostile_report):
    from pypdf import PdfReader

    first = " ".join(PdfReader(str(hostile_report / "evidence.pdf")).pages[0].extract_text().split())
    assert "Gate: FAILED" in first and "PASSED" not in first


def test_in_chromium_the_first_thing_shown_is_the_failed_gate(hostile_report):
    from selenium.webdriver.common.by import By

    d = browser()
    try:
        url = (hostile_report / "evidence.html").as_uri()
        d.get(url)
        assert d.current_url == url  # no refresh sent the browser elsewhere
        gate = d.find_element(By.CSS_SELECTOR, "#cover .gate")
        assert gate.is_displayed() and gate.text.startswith("Gate: FAILED")
        assert gate.size["height"] > 10 and d.find_element(By.ID, "cover").size["height"] > 100
        before = d.execute_script("return getComputedStyle(document.body, '::before').content")
        assert before in ("none", "normal", "")
        text = d.find_element(By.TAG_NAME, "body").text
        assert "Gate: FAILED" in text[:2000] and "Gate: PASSED" not in text[:text.index("Gate: FAILED")]
        assert d.execute_script("return document.querySelectorAll('script').length") == 1
        printed = d.execute_cdp_cmd("Page.printToPDF", {"printBackground": True})  # as the browser prints it
        first = " ".join(_pdf_page_one(base64.b64decode(printed["data"])).split())
        assert "Gate: FAILED" in first and "PASSED" not in first.split("Gate: FAILED")[0]
    finally:
        d.quit()
