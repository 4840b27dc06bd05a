"""The evidence report as a page to navigate: an anchor for every requirement, hazard, test and artefact, links
both ways, every requirement id a link, the argument inline with linked elements, test ids linked to their source,
full messages on demand, one inline script (a filter box) allowed by the page's Content-Security-Policy. Checked by
parsing the HTML (always) and in headless Chromium through Selenium (skipped, naming what is missing, without them).
"""

from __future__ import annotations

import os
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import hypothesis  # noqa: F401  # imported once here: the in-process pytest session would re-import it
import pytest

from assurance import cli
from assurance.evidence import generate

ROOT = Path(__file__).resolve().parents[1]
FAILING_TEST = '''
import pytest

@pytest.mark.requirements("EL-R13", "EL-R14")
def test_a_claim_that_fails(campaign_run):
    detail = "; ".join(f"shard {i} took longer than the budget allows" for i in range(12))
    assert False, "insufficient evidence: insufficient evidence: " + detail + "\\nsecond line of the message"
'''


@pytest.fixture(scope="module")
def nav_report(tiny_campaign, tmp_path_factory) -> Path:
    """A demo-like report: the tiny run, its requirement tests (the packaged ones and a user's failing one with a
    long message) as ``uav-el verify`` runs them, the evidence report (HTML)."""
    root = tmp_path_factory.mktemp("nav")
    (root / "mine").mkdir()
    (root / "mine" / "test_nav_claims.py").write_text(FAILING_TEST)
    out = root / "reports"
    cli.main(["verify", str(tiny_campaign["run"]), "--out", str(out), "--tests", str(root / "mine"),
              "-k", "not rerun"])
    return generate(tiny_campaign["run"], out, pdf=False, n_boot=50).html


class Page(HTMLParser):
    """The ids of a page and its internal links, each with the top-level section (or header) it lies in."""

    def __init__(self) -> None:
        super().__init__()
        self.ids: list[str] = []
        self.links: list[tuple[str, str]] = []  # (target, section id)
        self.attrs_of: dict[str, dict[str, str]] = {}
        self._stack: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = {k: v or "" for k, v in attrs}
        if tag in ("section", "header"):
            self._stack.append(a.get("id", ""))
        if "id" in a:
            self.ids.append(a["id"])
            self.attrs_of[a["id"]] = {**a, "section": self._stack[-1] if self._stack else ""}
        if a.get("href", "").startswith("#"):
            self.links.append((a["href"][1:], self._stack[-1] if self._stack else ""))

    def handle_endtag(self, tag):
        if tag in ("section", "header") and self._stack:
            self._stack.pop()


def parse(html: str) -> Page:
    page = Page()
    page.feed(html)
    return page


def linked_from(page: Page, target: str) -> set[str]:
    return {section for t, section in page.links if t == target}


def test_every_internal_link_has_its_anchor_and_every_requirement_is_linked(nav_report):
    from assurance import requirements as rq

    html = nav_report.read_text("utf-8")
    page = parse(html)
    assert len(page.ids) == len(set(page.ids)), "an id used twice"
    missing = sorted({t for t, _ in page.links} - set(page.ids))
    assert not missing, f"links without an anchor: {missing[:10]}"
    for rid in rq.load_registry(None).ids:
        assert page.attrs_of[f"req-{rid}"]["section"] == "matrix", rid  # the requirement's anchor: its matrix row
        assert page.attrs_of[f"reqtext-{rid}"]["section"] == "requirements", rid
        sections = linked_from(page, f"req-{rid}")
        assert {"cover", "argument", "requirements"} <= sections, (rid, sections)
        assert "matrix" in linked_from(page, f"reqtext-{rid}"), rid
    hazards = [i for i in page.ids if i.startswith("haz-")]
    assert hazards and all("matrix" in linked_from(page, h) for h in hazards)  # and back from the requirement
    assert all("hazards" in linked_from(page, f"req-{rid}") for rid in ("EL-R01", "EL-R04"))


def test_no_requirement_id_is_left_as_plain_text(nav_report):
    html = nav_report.read_text("utf-8")
    text = re.sub(r"<(script|style|svg|title|pre)\b.*?</\1>|<a\b.*?</a>", " ", html, flags=re.S | re.I)
    text = re.sub(r"<[^>]*>", " ", text)
    assert not re.findall(r"(?<![\w-])EL-R\d\d(?![\w-])", text)


def test_tests_and_artefacts_have_anchors_and_links_to_their_files(nav_report):
    html = nav_report.read_text("utf-8")
    page = parse(html)
    out = nav_report.parent
    tests = [i for i in page.ids if i.startswith("test-")]
    assert len(tests) > 5 and all(page.attrs_of[t]["section"] == "tests" for t in tests)
    assert all("matrix" in linked_from(page, t) for t in tests)  # requirement -> claiming test
    sources = re.findall(r'<a href="([^"#]+\.py)#L(\d+)">', html)
    assert sources and all((out / f).is_file() for f, _ in sources)
    for f, line in sources:  # the line is the test function's
        assert (out / f).read_text("utf-8").splitlines()[int(line) - 1].lstrip().startswith(("def test", "async def"))
    assert "The tests ran on the toolkit&#39;s code version" in html  # the code identity the links are read against
    for name in ("results.csv", "evidence.json", "traceability.csv", "junit.xml"):
        assert page.attrs_of[f"art-{name}"]["section"] == "files"
        assert f'<a href="{name}">' in html
        assert (out / name).is_file()
    assert "matrix" in linked_from(page, "art-results.csv")


def test_messages_are_whole_and_said_once_and_the_page_says_bca(nav_report):
    html = nav_report.read_text("utf-8")
    assert "insufficient evidence: insufficient evidence" not in html
    assert html.count("second line of the message") >= 2  # in full, behind its summary, in matrix and test list
    assert re.search(r'<details class="msg"><summary>[^<]*shard 0 took longer', html)
    assert "percentile-bootstrap" not in html and "percentile bootstrap" not in html and "BCa" in html


def test_one_script_allowed_by_its_hash_and_the_argument_inline(nav_report):
    from assurance.evidence.linking import SCRIPT, script_hash

    html = nav_report.read_text("utf-8")
    assert html.count("<script") == 1 and f"<script>{SCRIPT}</script>" in html
    csp = re.search(r'<meta http-equiv="Content-Security-Policy" content="([^"]+)">', html)
    assert csp and f"script-src '{script_hash()}'" in csp.group(1) and "default-src 'none'" in csp.group(1)
    assert html.index("Content-Security-Policy") < html.index("<style>")  # before anything it governs
    assert "data:image/svg+xml" not in html and html.count('<div class="gsn-view"') == 4
    assert 'id="gsn-G-EL-R01"' in html


# -- in a real browser -------------------------------------------------------------------------------------------
def browser():
    """A headless Chromium driven by Selenium through Debian's chromedriver; skipped naming what is missing."""
    try:
        from selenium import webdriver
    except ImportError as exc:
        pytest.skip(f"selenium not installed ({exc}; pip install 'uav-el-assurance[browser]')")
    binary = next(filter(None, (shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome"))), None)
    driver_path = shutil.which("chromedriver")
    if binary is None or driver_path is None:
        pytest.skip("chromium or chromedriver not installed (.ci/browser-deps installs them)")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1280,900"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(executable_path=driver_path), options=opts)


@pytest.fixture(scope="module")
def page_in_chromium(request):
    driver = browser()  # skips before the report is built when the browser is missing
    try:
        driver.get(request.getfixturevalue("nav_report").as_uri())
        yield driver
    finally:
        driver.quit()


def test_in_chromium_every_link_lands_on_its_anchor(page_in_chromium):
    from selenium.webdriver.common.by import By

    d = page_in_chromium
    shots = Path(os.environ.get("UAV_EL_SCREENSHOTS") or ROOT / "reports" / "screenshots")
    shots.mkdir(parents=True, exist_ok=True)
    assert d.save_screenshot(str(shots / "evidence-first-screen.png"))  # the first screen, a CI artefact
    targets = d.execute_script("return Array.from(document.querySelectorAll('a[href^=\"#\"]'),"
                               " a => decodeURIComponent(a.getAttribute('href').slice(1)));")
    assert len(targets) > 100
    landed = d.execute_script("""
        const bad = [];
        for (const t of new Set(arguments[0])) {
          location.hash = '#' + t;
          const at = document.querySelector(':target');
          if (!at || at.id !== t) bad.push(t);
        }
        return bad;""", targets)
    assert landed == []
    d.get(d.current_url.split("#")[0])
    chain = ["#req-EL-R01", "#haz-H1", "#req-EL-R01"]  # summary -> requirement -> hazard -> back
    d.find_element(By.CSS_SELECTOR, f'header#cover a[href="{chain[0]}"]').click()
    d.find_element(By.CSS_SELECTOR, f'tr{chain[0]} a[href="{chain[1]}"]').click()
    d.find_element(By.CSS_SELECTOR, f'tr{chain[1]} a[href="{chain[2]}"]').click()
    test_link = d.find_element(By.CSS_SELECTOR, "tr#req-EL-R01 a.test")
    test_link.click()  # requirement -> its test -> the test's file
    row = d.find_element(By.ID, test_link.get_attribute("hash")[1:])
    assert row.is_displayed() and ".py#L" in row.find_element(By.CSS_SELECTOR, "a[href*='.py']").get_attribute("href")
    severe = [e for e in d.get_log("browser") if e["level"] == "SEVERE"]
    assert severe == []  # no script refused by the policy, nothing fetched


def test_in_chromium_the_filter_box_hides_the_other_rows(page_in_chromium):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d = page_in_chromium
    d.get(d.current_url.split("#")[0])
    box = d.find_element(By.CSS_SELECTOR, "#matrix .filter input")
    rows = d.find_elements(By.CSS_SELECTOR, "table.matrix tbody tr")
    assert len(rows) > 10 and all(r.is_displayed() for r in rows)
    box.send_keys("EL-R05")
    assert [r.get_attribute("id") for r in rows if r.is_displayed()] == ["req-EL-R05"]
    box.clear()
    box.send_keys(" ")  # an input event: every row again
    Select(d.find_element(By.CSS_SELECTOR, "#matrix .filter select")).select_by_visible_text("failed")
    shown = [r for r in rows if r.is_displayed()]
    assert shown and all(r.get_attribute("data-state") == "failed" for r in shown)
    tests_box = d.find_element(By.CSS_SELECTOR, "#tests .filter input")
    tests_box.send_keys("EL-R14")
    shown = [r for r in d.find_elements(By.CSS_SELECTOR, "table.testlist tbody tr") if r.is_displayed()]
    assert shown and all("EL-R14" in r.get_attribute("data-ids").split() for r in shown)
    details = d.find_element(By.CSS_SELECTOR, "#tests details.msg")
    full = details.find_element(By.CSS_SELECTOR, ".full")
    assert not full.is_displayed()
    details.find_element(By.TAG_NAME, "summary").click()
    assert full.is_displayed() and "second line of the message" in full.text


def test_with_a_baseline_each_requirement_says_what_changed(nav_report, tiny_campaign, tmp_path):
    import json

    doc = json.loads((nav_report.parent / "requirements.json").read_text("utf-8"))
    req = doc["requirements"]["EL-R05"]
    moved = req["tests"][0]
    moved["outcome"], moved["message"] = "failed", "failed in the baseline"
    req["state"], req["reason"] = "failed", "1 of 3 claiming test(s) failed"
    base = tmp_path / "baseline-requirements.json"
    base.write_text(json.dumps(doc), "utf-8")
    html = generate(tiny_campaign["run"], tmp_path / "r", requirements=nav_report.parent / "requirements.json",
                    baseline=tiny_campaign["run"], baseline_requirements=base, pdf=False, n_boot=20
                    ).html.read_text("utf-8")
    row = re.search(r'<tr id="req-EL-R05".*?</tr>', html, re.S).group(0)
    assert "baseline: failed (changed); 1 test(s) changed" in row and 'href="#changes"' in row
    changes = html[html.index('<section id="changes"'):]
    changes = changes[:changes.index("</section>")]
    first_test = re.search(r'<a class="test" href="(#test-[^"]+)"', row).group(1)
    assert f'href="{first_test}"' in changes  # the test that changed, linked to its entry
    assert "failed &rarr; passed" in changes and "1 requirement state(s) changed" in changes
    assert 'href="#req-EL-R06"' not in changes  # unchanged requirements are not listed


def test_a_section_is_added_through_the_registry(monkeypatch):
    from assurance.evidence import outline as ol

    monkeypatch.setattr(ol, "SECTIONS", list(ol.SECTIONS))
    ol.register_section(ol.Section("extra", "An extra section", "section_extra.html.j2", when="bench"))
    with pytest.raises(ValueError, match="already registered"):
        ol.register_section(ol.Section("extra", "again", "x.html.j2"))
    with pytest.raises(ValueError, match="not registered"):
        ol.register_section(ol.Section("other", "other", "x.html.j2"), after="nowhere")
    ids = [s["id"] for s in ol.outline({"bench": True, "faults": [1]})["sections"]]
    assert ids[-3:] == ["reproduce", "extra", "faults"]
    shown = ol.outline({})
    assert "extra" not in [s["id"] for s in shown["sections"]]  # its context value unset: not shown
    assert shown["section_templates"].count("auditor_records.html.j2") == 1  # a shared template included once
