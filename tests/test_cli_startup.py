"""``uav-el --help`` and ``--version`` start fast: they import no command and none of the commands' heavy
dependencies; a command imports what it needs when it runs or shows its own help."""

from __future__ import annotations

import subprocess
import sys

import pytest

from assurance import cli

HEAVY = ("torch", "pandas", "scipy", "onnxruntime", "weasyprint", "dask", "sklearn", "PIL")


def _imported(args: list[str]) -> set[str]:
    code = ("import sys; from assurance.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "print(' '.join(sorted(m.split('.')[0] for m in sys.modules)), file=sys.stderr)")
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
    return set(done.stderr.strip().splitlines()[-1].split())


@pytest.mark.parametrize("args", [["--version"], ["--help"], ["-v", "--help"]])
def test_help_and_version_import_no_heavy_dependency(args):
    loaded = _imported(args)
    assert not loaded & set(HEAVY), loaded & set(HEAVY)


def test_a_command_s_help_imports_that_command_only():
    loaded = _imported(["keys", "--help"])
    assert not loaded & {"torch", "pandas"}, loaded


def test_every_command_has_its_one_line_summary():
    assert set(cli.SUMMARIES) == set(cli.COMMANDS)
    assert all(len(s) < 100 for s in cli.SUMMARIES.values())


def test_the_chosen_command_is_found_past_global_options():
    assert cli._chosen(["-v", "--log-level", "DEBUG", "land", "x.png"]) == "land"
    assert cli._chosen(["--log-level", "land"]) is None  # "land" is the option's value here
    assert cli._chosen(["--help"]) is None and cli._chosen(["nosuch"]) is None
