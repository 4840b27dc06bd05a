"""The auditor's two critical holes, closed: an applicant's report templates run in Jinja2's immutable sandbox
(no Python internals, exit 2 naming the file and line), cannot state a gate verdict the gate did not give or
replace the first page, and the PDF renderer reads nothing but data: URIs and the report's own files."""

from __future__ import annotations

import json

import pytest

from assurance import cli
from assurance.evidence.render import TemplateError, render_html, verdict_phrases


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


def test_a_template_claiming_passed_on_a_failed_gate_is_refused(tiny_campaign, tmp_path, monkeypatch, capsys):
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "ref", "--no-pdf", "--boot", 50)
    capsys.readouterr()
    verdict = json.loads((tmp_path / "ref" / "evidence.json").read_text("utf-8"))["gate"]["result"]
    assert verdict != "PASSED" and code == 1
    claims = ("<h1>Gate: PASSED</h1>", "<p>gate &mdash; <b>passed</b></p>", "{{ 'Gate: ' ~ 'PAS' ~ 'SED' }}",
              "<style>.x::before { content: 'gate, pass' }</style>")
    mine = _folder(tmp_path, "auditor_issre.html.j2", "<section>\n" + "\n".join(claims) + "\n</section>\n")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot",
                     50, "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2 and "gate verdict the gate did not give" in err and verdict in err, err
    for said in ("'Gate: PASSED'", "'gate — passed'", "'gate, pass'"):
        assert said in err, (said, err)


def test_the_first_page_is_the_toolkits_whatever_the_templates(tiny_campaign, tmp_path, monkeypatch, capsys):
    mine = _folder(tmp_path, "report.html.j2", "<!DOCTYPE html><html><head><title>x</title></head>"
                   "<body><p>All good, nothing to see.</p></body></html>\n")
    (mine / "cover.html.j2").write_text("<body><p>replaced cover</p></body>", "utf-8")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    capsys.readouterr()
    html = (tmp_path / "r" / "evidence.html").read_text("utf-8")
    verdict = json.loads((tmp_path / "r" / "evidence.json").read_text("utf-8"))["gate"]["result"]
    assert code == 1
    assert "replaced cover" not in html
    body = html.index("<body>")
    assert html.index('id="cover"') < html.index("All good") and html.index('id="cover"') > body
    assert f"Gate: {verdict}" in html
    mine = _folder(tmp_path, "report.html.j2", "<p>no body element</p>")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r2", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    assert code == 2 and "no <body>" in capsys.readouterr().err


def test_verdict_phrases_count_only_other_verdicts():
    html = "<p>Gate: <b>FAILED</b></p><p>gate passed</p><p>the gate: passed</p><p>gateway passed</p>"
    assert sum(verdict_phrases(html, "FAILED").values()) == 2
    assert sum(verdict_phrases(html, "PASSED").values()) == 1


def test_render_html_quotes_of_the_evidence_are_not_claims(tmp_path):
    """A supplied template that shows a value holding "gate: PASSED" (as the packaged one does) is not refused."""
    mine = tmp_path / "t"
    mine.mkdir()
    (mine / "report.html.j2").write_text("<html><body><p>{{ note }}</p><p>{{ extra }}</p></body></html>", "utf-8")
    ctx = {"gate": "FAILED", "note": "expected: gate: PASSED", "extra": ""}
    with pytest.raises(TemplateError):  # the packaged report does not show `note`: the claim is the template's
        render_html(ctx, mine)


weasyprint = pytest.importorskip("weasyprint")


def test_an_attachment_of_a_local_file_is_refused_exit_2(tiny_campaign, tmp_path, monkeypatch, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("SIGNING-KEY-BYTES", "utf-8")
    mine = _folder(tmp_path, "auditor_issre.html.j2",
                   f'<section>\n<link rel="attachment" href="file://{secret}">\n</section>\n')
    out = tmp_path / "out" / "r"
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", out, "--boot", 50, "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "refuses" in err and f"file://{secret}" in err, err
    assert not (out / "evidence.pdf").exists() and not (out / "evidence.html").exists()
    assert not list(out.glob(".*.tmp"))


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
