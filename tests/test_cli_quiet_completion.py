"""The command line: ``-q`` quiets every command (nothing on stdout but what a command exists to print, no
progress), and ``uav-el --completion SHELL`` prints a completion script of every command (shtab)."""

from __future__ import annotations

import pytest

from assurance import cli


def test_q_leaves_nothing_on_stdout_or_stderr(tmp_path, capsys):
    assert cli.main(["synth", "--out", str(tmp_path / "d"), "--scenes", "1", "--size", "64x36", "-q"]) == 0
    assert capsys.readouterr() == ("", "")
    assert cli.main(["-q", "synth", "--out", str(tmp_path / "e"), "--scenes", "1", "--size", "64x36"]) == 0
    assert capsys.readouterr() == ("", "")
    assert cli.main(["synth", "--out", str(tmp_path / "f"), "--scenes", "1", "--size", "64x36"]) == 0
    assert "1 scene(s) written" in capsys.readouterr().out  # without -q the summary is there


def test_q_keeps_an_error_on_stderr(tmp_path, capsys):
    assert cli.main(["table", str(tmp_path / "no-run"), "-q"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("uav-el table: error:")


@pytest.mark.parametrize("shell", ["bash", "zsh"])
def test_completion_lists_every_command(shell, capsys):
    pytest.importorskip("shtab")
    with pytest.raises(SystemExit) as done:
        cli.main(["--completion", shell])
    assert done.value.code == 0
    script = capsys.readouterr().out
    assert all(name in script for name in cli.COMMANDS) and "--monitors" in script
