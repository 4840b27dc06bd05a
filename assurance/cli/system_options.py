"""What a command takes from the system file (``--system``), with options given on the command line winning."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.errors import CommandError, RunError
from assurance.system import SystemFile, default_system
from assurance.system.loader import SystemFileError, system_from_record
from assurance.system.system import System
from el.base import userfiles


def train_val_dirs(args: argparse.Namespace, system: SystemFile) -> None:
    """Resolve ``args.data`` and ``args.val`` (the options, else the system file's ``[data]`` train and val) and
    refuse a folder that is not there (one line naming it)."""
    args.data = system.data("train", args.data)
    args.val = system.data("val", args.val)
    for d in (args.data, args.val):
        if not Path(d).is_dir():
            raise CommandError(f"{d}: no such folder")


def system_of(args: argparse.Namespace) -> SystemFile:
    """The command's system file (``uav-el`` resolved it before the command ran; the default otherwise)."""
    system = getattr(args, "system_file", None)
    return system if system is not None else default_system()


def assessed(args: argparse.Namespace) -> System:
    """The system under assessment of the command: its system file with the ``--model`` and ``--gate`` given,
    built and checked once (``assurance.system.System``) and kept on ``args``."""
    system = getattr(args, "assessed_system", None)
    if system is None:
        system = System.build(system_of(args), model=getattr(args, "weights", None), gate=getattr(args, "gate", None))
        args.assessed_system = system
    return system


def run_system(args: argparse.Namespace, run: Path) -> SystemFile:
    """The system file a command about a run (``evidence``, ``verify``, ``in-service``) judges: the one given with
    ``--system``; else the run's own as its signed manifest records it (the document itself: no file at the path
    the manifest names is read), also over a ``uav-el.toml`` found in the working directory (a note says when that
    file is not the run's); else the file found there; else the embedded default. Says which one it judges, and
    why (stdout)."""
    system = system_of(args)
    if not system.default and getattr(args, "system", None):
        _say_judged(f"{system.label} (given)")
        return system
    found = _recorded_system(run)
    if found is None:
        if not system.default:
            _say_judged(f"{system.label} (found in the working directory; the run records no system file)")
        else:
            _say_judged("the embedded default (the shipped system; the run records no other)")
        return system
    _say_judged(f"{found.label} (the run's own)")
    if not system.default and system.sha256 != found.sha256:
        print(f"note: {system.label} in the working directory is not the run's system file (SHA-256 "
              f"{system.sha256[:12]}, the run's {found.sha256[:12]}): the run's recorded copy is judged; a new "
              "campaign with that file makes the evidence of it")
    else:
        changed = _changed_since(found)
        if changed:
            print(changed)
    return found


def _changed_since(recorded: SystemFile) -> str | None:
    """A note when the file at the path the run records is no longer the file the run was made with (by SHA-256
    only, through the bounded reader: nothing of it is read into the report); None when it is, or is gone."""
    try:
        now = userfiles.sha256(recorded.path, what="system file", max_bytes=userfiles.MAX_SETTINGS_BYTES)
    except (OSError, userfiles.UserFileError):
        return None
    if not recorded.sha256 or now == recorded.sha256:
        return None
    return (f"note: {recorded.path} has changed since the run (SHA-256 {now[:12]} now, {recorded.sha256[:12]} when "
            "the run was made): the run's own recorded copy is judged; a new campaign with the file as it is now "
            "makes the evidence of it")


def _recorded_system(run: Path) -> SystemFile | None:
    """The system file the run's signed manifest records, None when it records the default (or none)."""
    from assurance.campaign.readouts import read_manifest  # deferred: pulls in pandas; keeps the commands' --help light

    try:
        recorded = read_manifest(run).get("system") or {}
    except (OSError, ValueError, RunError):
        return None  # the report's own run checks name what is wrong with the run
    if not isinstance(recorded, dict) or recorded.get("default", True) or not recorded.get("document"):
        return None  # what is not a record is no system: the report's run checks name the damage
    try:
        return system_from_record(recorded)
    except SystemFileError as exc:
        raise SystemFileError(f"{run / 'manifest.json'}: the system file it records: {exc}") from None


def _say_judged(what: str) -> None:
    """One line on stdout (stderr stays the one line that says what went wrong, when something does)."""
    print(f"system judged: {what}")
