"""What a command takes from the system file (``--system``), with options given on the command line winning."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.system import SystemFile, default_system
from assurance.system.system import System


def train_val_dirs(args: argparse.Namespace, system: SystemFile) -> None:
    """Resolve ``args.data`` and ``args.val`` (the options, else the system file's ``[data]`` train and val) and
    refuse a folder that is not there (one line naming it)."""
    from assurance.errors import CommandError
    from assurance.system import build as system_build

    args.data = system_build.data_root(system, "train", args.data)
    args.val = system_build.data_root(system, "val", args.val)
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
