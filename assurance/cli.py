"""``uav-el``: the command line. A thin layer: parse arguments, call the library, format output.

Each sub-command lives in ``assurance/commands/<name>.py`` and exposes ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. Expected errors (bad input files, bad
options) are printed as one line naming the file and the problem, with a non-zero exit code.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from assurance import __version__

# Sub-command name -> module under assurance.commands. Order is the order of `uav-el --help`.
COMMANDS: dict[str, str] = {
    "synth": "synth",
    "preview": "preview",
    "land": "land",
    "train": "train",
    "model-card": "model_card",
    "campaign": "campaign",
    "calibrate": "calibrate",
    "fit-monitor": "fit_monitor",
    "fit-ood": "fit_ood",
    "table": "table",
    "evidence": "evidence",
}


class CommandError(Exception):
    """An expected failure of a command: printed as one line, exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="uav-el",
        description="Safety-assurance toolkit for UAV emergency landing.",
    )
    parser.add_argument("--version", action="version", version=f"uav-el {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(f"assurance.commands.{module_name}")
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``uav-el``; returns the exit code."""
    from el.labels import LabelColourError
    from el.uavid import DataError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (CommandError, DataError, LabelColourError, FileNotFoundError, ValueError) as exc:
        print(f"uav-el {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"uav-el {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
