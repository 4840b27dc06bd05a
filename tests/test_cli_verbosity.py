"""-v / -q on every command (before or after its name), and log records as one line each by default: warnings
shown, tracebacks only with -v."""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

from assurance import cli


@pytest.mark.parametrize("name", list(cli.COMMANDS))
def test_every_command_takes_v_and_q(name):
    parser = cli.build_parser()
    sub = parser._subparsers._group_actions[0].choices[name]
    assert "-v" in sub._option_string_actions and "-q" in sub._option_string_actions


def test_q_after_the_command_and_before_it():
    parser = cli.build_parser()
    args = parser.parse_args(["table", "RUN", "-q"])
    assert args.quiet == 1 and args.verbose == 0
    args = parser.parse_args(["-q", "table", "RUN"])
    assert args.log_quiet == 1
    args = parser.parse_args(["campaign", "--out", "r", "-q", "-vv"])
    assert args.quiet is True and args.verbose == 2


def test_a_logged_fault_is_one_line_unless_verbose():
    try:
        raise RuntimeError("boom")
    except RuntimeError:
        record = logging.LogRecord("el.flight.pipeline", logging.ERROR, __file__, 1, "fault in stage %s", ("x",),
                                   sys.exc_info())
    brief = cli._OneLine(tracebacks=False).format(record)
    assert brief == "ERROR el.flight.pipeline: fault in stage x"
    assert "Traceback" in cli._OneLine(tracebacks=True).format(record)


def test_warnings_show_by_default_and_q_hides_them(tmp_path):
    script = ("import logging, sys; from assurance import cli; "
              "args = cli.build_parser().parse_args(sys.argv[1:]); cli.configure_logging(args); "
              "logging.getLogger('assurance.x').warning('careful'); logging.getLogger('assurance.x').info('detail'); "
              "logging.getLogger('weasyprint').warning('font')")  # a PDF library's font notes: only with -v
    run = [sys.executable, "-c", script]
    out = subprocess.run([*run, "table", "RUN"], capture_output=True, text=True, timeout=120)
    assert out.stderr.strip() == "WARNING assurance.x: careful"
    out = subprocess.run([*run, "table", "RUN", "-q"], capture_output=True, text=True, timeout=120)
    assert out.stderr.strip() == ""
    out = subprocess.run([*run, "-v", "table", "RUN"], capture_output=True, text=True, timeout=120)
    assert "INFO assurance.x: detail" in out.stderr and "weasyprint: font" in out.stderr
