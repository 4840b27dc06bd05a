"""An applicant's report templates: section bodies only, rendered in Jinja2's immutable sandbox (no Python internals,
exit 2 naming the file and line) inside a child with time and memory limits, cleaned to an allow-list of markup; the
shell (head, CSP, stylesheet, first page) is the toolkit's whatever the folder holds, and the PDF renderer reads
nothing but data: URIs and the report's own files."""

from __future__ import annotations

import json

import pytest

from assurance import cli


def _evidence(monkeypatch, *args):
    monkeypatch.setitem(cli.COMMANDS, "evidence", "evidence")
    return cli.main(["evidence", *map(str, args)])


def _folder(tmp_path, name, text):
    mine = tmp_path / "applicant_templates"
    mine.mkdir(exist_ok=True)
    (mine / name).write_text(text, "utf-8")
    return mine


@pytest.mark.parametrize("escape", [
    "{{ cycler.__init__.__globals__.os.system('touch %s') }}",
    "{{ ''.__class__.__mro__[1].__subclasses__() }}",
    "{{ joiner.__init__.__globals__['os'].popen('touch %s').read() }}",
])
def test_a_template_reaching_python_internals_is_refused_exit_2(escape, tiny_campaign, tmp_path, monkeypatch, capsys):
    marker = tmp_path / "pwned"
    text = escape.replace("%s", str(marker)) if "%s" in escape else escape
    mine = _folder(tmp_path, "auditor_issre.html.j2", "<section>\n<p>ok</p>\n" + text + "\n</section>\n")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "auditor_issre.html.j2:3" in err and "refused" in err, err
    assert not marker.exists()
    assert not (tmp_path / "r" / "evidence.html").exists()


def test_a_template_cannot_modify_what_it_is_given(tiny_campaign, tmp_path, monkeypatch, capsys):
    mine = _folder(tmp_path, "auditor_issre.html.j2", "<section>\n{{ problems.append('x') }}\n</section>\n")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2 and "auditor_issre.html.j2:2" in err, err


def _gate(tmp_path, name="r"):
    return json.loads((tmp_path / name / "evidence.json").read_text("utf-8"))["gate"]["result"]


def test_a_section_claiming_passed_stays_a_section_the_first_page_says_the_gate(tiny_campaign, tmp_path,
                                                                               monkeypatch, capsys):
    claims = ("<h1>Gate: PASSED</h1>", "<p class='gate verified'>gate &mdash; <b>passed</b></p>",
              "<style>.cover { display: none }</style>", "<script>document.body.innerHTML = 'PASSED'</script>",
              '<meta http-equiv="refresh" content="0; url=http://127.0.0.1:9/?d=x">', "<div data-x='>",
              "<p onclick='x()' style='position:fixed'>styled</p><!-- <body> -->")
    mine = _folder(tmp_path, "auditor_issre.html.j2", "<section id='issre'>\n" + "\n".join(claims) + "\n</section>\n")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot",
                     50, "--templates", mine)
    capsys.readouterr()
    verdict = _gate(tmp_path)
    assert verdict != "PASSED" and code == 1
    html = (tmp_path / "r" / "evidence.html").read_text("utf-8")
    body = html[html.index("<body>"):]
    assert body.index('id="cover"') < body.index("Gate: PASSED"), "the claim comes after the first page"
    assert f"Gate: {verdict}" in body[:body.index('id="issre"')]
    for gone in ("<h1>Gate: PASSED", 'class="gate verified"', ".cover { display", "innerHTML", "refresh",
                 "127.0.0.1", "onclick", "position:fixed", "data-x"):
        assert gone not in html, gone
    assert html.count("<script>") == 1 and html.count("<style>") == 1
    assert html.count("Content-Security-Policy") == 1 and html.index("Content-Security-Policy") < html.index("<title>")
    assert "The section below is the applicant's" in body and str(mine) in body


def test_the_shell_and_stylesheet_are_the_toolkits_whatever_the_folder(tiny_campaign, tmp_path, monkeypatch,
                                                                        capsys):
    mine = _folder(tmp_path, "report.html.j2", "<!DOCTYPE html><html><head data-x='><!-- <body> -->"
                   "<title>x</title></head><body><p>All good, nothing to see.</p></body></html>\n")
    (mine / "cover.html.j2").write_text("<p>replaced cover: Gate: PASSED</p>", "utf-8")
    (mine / "evidence.css").write_text(".cover { max-height: 0; overflow: hidden } body::before { content: "
                                       "'\\47 ate: PASSED' }", "utf-8")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    capsys.readouterr()
    html = (tmp_path / "r" / "evidence.html").read_text("utf-8")
    assert code == 1
    for gone in ("replaced cover", "All good", "max-height: 0", "\\47 ate"):
        assert gone not in html, gone
    assert f"Gate: {_gate(tmp_path)}" in html
    cover = html[html.index('id="cover"'):html.index('class="toc"')]
    for name in ("report.html.j2", "cover.html.j2", "evidence.css"):
        assert f"<code>{name}</code>" in cover, name  # named on the first page as not used


def test_the_system_files_templates_are_used_only_when_asked(tiny_campaign, tmp_path, monkeypatch, capsys):
    mine = _folder(tmp_path, "section_limitations.html.j2", "<section id='limitations'><p>MY LIMITS</p></section>")
    system = tmp_path / "uav-el.toml"
    system.write_text(f'format = "uav-el-system/1"\n[report]\ntemplates = "{mine}"\n', "utf-8")
    for flags, shown in (((), False), (("--system-templates",), True)):
        out = tmp_path / f"r{len(flags)}"
        _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", out, "--no-pdf", "--boot", 50,
                  "--system", system, *flags)
        capsys.readouterr()
        html = (out / "evidence.html").read_text("utf-8")
        assert ("MY LIMITS" in html) is shown
        assert (str(mine) in html[:html.index('class="toc"')]) is shown
        doc = json.loads((out / "evidence.json").read_text("utf-8"))
        assert (doc["templates"] is not None) is shown


@pytest.mark.parametrize(("body", "said"), [
    ("{% for i in range(100000) %}{% for j in range(100000) %}{% endfor %}{% endfor %}", "did not finish"),
    ("{{ ('x' * 10**10) | length }}", "memory"),
    ('{% include "auditor_issre.html.j2" %}', "recurses"),
])
def test_an_endless_or_greedy_template_is_refused_naming_it(body, said, tiny_campaign, tmp_path, monkeypatch, capsys):
    from assurance import bounded

    monkeypatch.setattr(bounded, "SECONDS", 4.0)
    mine = _folder(tmp_path, "auditor_issre.html.j2", f"<section id='issre'>{body}</section>")
    out = tmp_path / "r"
    out.mkdir()
    for name in ("evidence.html", "evidence.json", "evidence.pdf"):  # an earlier report in the folder
        (out / name).write_text("earlier", "utf-8")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", out, "--no-pdf", "--boot", 50,
                     "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2 and "auditor_issre.html.j2" in err and said in err, err
    assert "Traceback" not in err
    assert not any((out / n).exists() for n in ("evidence.html", "evidence.json", "evidence.pdf"))


def test_the_sanitiser_keeps_section_markup_and_drops_the_rest():
    from assurance.evidence.sanitise import clean_fragment

    out = clean_fragment('<section id="issre"><h2>T</h2><table><tr><td colspan="2" class="num gate">1</td></tr>'
                         '</table><a href="#req-EL-R01">r</a><a href="https://x.test/">x</a><img src="file:///k">'
                         '<img src="data:image/png;base64,AAAA" alt="a"><div id="cover">c</div></section>'
                         '<!-- unclosed <p>rest', {"issre"})
    assert '<section id="issre"><h2>T</h2>' in out and '<td colspan="2" class="num">1</td>' in out
    assert '<a href="#req-EL-R01">r</a>' in out and "x.test" not in out and "file:" not in out
    assert 'src="data:image/png;base64,AAAA"' in out and 'id="supplied-cover"' in out
    assert "rest" not in out and "<!--" not in out


weasyprint = pytest.importorskip("weasyprint")


def test_a_supplied_attachment_of_a_local_file_never_reaches_the_pdf(tiny_campaign, tmp_path, monkeypatch, capsys):
    from pypdf import PdfReader

    secret = tmp_path / "secret.txt"
    secret.write_text("SIGNING-KEY-BYTES", "utf-8")
    mine = _folder(tmp_path, "auditor_issre.html.j2",
                   f'<section id="issre">\n<link rel="attachment" href="file://{secret}">'
                   f'<img src="file://{secret}"><p>Gate: PASSED</p>\n</section>\n')
    out = tmp_path / "out" / "r"
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", out, "--boot", 50, "--templates", mine)
    err = capsys.readouterr().err
    assert code == 1, err
    assert "secret.txt" not in (out / "evidence.html").read_text("utf-8")
    reader = PdfReader(str(out / "evidence.pdf"))
    assert "secret.txt" not in reader.attachments
    first = reader.pages[0].extract_text()
    assert f"Gate: {_gate(tmp_path / 'out')}" in first and "PASSED" not in first


@pytest.mark.parametrize("element", [
    '<link rel="attachment" href="file://{path}">',
    '<img src="file://{path}">',
    '<link rel="stylesheet" href="file://{path}">',
    '<style>@import url("file://{path}");</style>',
    '<style>@font-face {{ font-family: x; src: url("file://{path}"); }} p {{ font-family: x }}</style>',
    '<img src="http://127.0.0.1:9/x.png">',
    '<link rel="attachment" href="secret.txt">',
    '<img src="ftp://127.0.0.1/x.png">',
])
def test_write_pdf_reads_no_local_file_nor_the_network(element, tmp_path):
    from assurance.evidence.render import RefusedResourceError, write_pdf

    secret = tmp_path / "secret.txt"
    secret.write_text("SIGNING-KEY-BYTES", "utf-8")
    own = tmp_path / "own.json"
    own.write_text("{}", "utf-8")
    html = "<html><body><p>report</p>" + element.format(path=secret) + "</body></html>"
    with pytest.raises(RefusedResourceError, match="refuses"):
        write_pdf(html, tmp_path / "evidence.pdf", [own], served=[own])
    assert not (tmp_path / "evidence.pdf").exists()


def test_write_pdf_serves_data_uris_and_its_own_files(tmp_path):
    from assurance.evidence.render import pdf_attachment_names, write_pdf

    own = tmp_path / "own.csv"
    own.write_text("a,b\n", "utf-8")
    pixel = ("data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQ"
             "AAAABJRU5ErkJggg==")
    html = f'<html><body><img src="{pixel}"><link rel="attachment" href="own.csv"></body></html>'
    assert write_pdf(html, tmp_path / "evidence.pdf", [], served=[own]) is None
    assert "own.csv" in pdf_attachment_names(tmp_path / "evidence.pdf")
