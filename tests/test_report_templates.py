"""Section templates a user replaces: a folder given by option (or the system file's, with --system-templates)
replaces the packaged section templates file by file; a broken template is exit 2 naming the file and the line."""

from __future__ import annotations

from assurance import cli


def _evidence(monkeypatch, *args):
    monkeypatch.setitem(cli.COMMANDS, "evidence", "evidence")
    return cli.main(["evidence", *map(str, args)])


def test_a_user_template_replaces_the_packaged_one(tiny_campaign, tmp_path, monkeypatch, capsys):
    mine = tmp_path / "evidence_templates"
    mine.mkdir()
    (mine / "auditor_hazards.html.j2").write_text(
        '<section id="hazards"><h2>Our hazards</h2>{% for h in hazards %}<p>{{ h.id }}: {{ h.hazard }}</p>'
        '{% endfor %}<p>{{ "<b>" }}</p></section>\n', "utf-8")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    assert code in (0, 1), capsys.readouterr()
    html = (tmp_path / "r" / "evidence.html").read_text("utf-8")
    assert "<h2>Our hazards</h2>" in html and "<p>H1: " in html
    assert "&lt;b&gt;" in html  # autoescape holds in a user's template too
    assert 'id="argument"' in html  # the other sections still come from the package


def test_a_broken_template_is_exit_2_naming_file_and_line(tiny_campaign, tmp_path, monkeypatch, capsys):
    mine = tmp_path / "tpl"
    mine.mkdir()
    (mine / "auditor_issre.html.j2").write_text("<section>\n<p>fine</p>\n{% for r in issre_rows %}\n</section>\n",
                                                "utf-8")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2
    assert "auditor_issre.html.j2:4" in err and "does not compile" in err, err
    (mine / "auditor_issre.html.j2").write_text("<section>\n<p>{{ no_such_value.x }}</p>\n</section>\n", "utf-8")
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--no-pdf", "--boot", 50,
                     "--templates", mine)
    err = capsys.readouterr().err
    assert code == 2 and "auditor_issre.html.j2:2" in err and "no_such_value" in err, err
    code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", tmp_path / "r", "--templates",
                     tmp_path / "missing")
    assert code == 2 and "missing" in capsys.readouterr().err
