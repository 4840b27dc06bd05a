"""What a command takes from the system file (``--system``), with options given on the command line winning."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from assurance.system import SystemFile, default_system
from assurance.system import build as system_build


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


def is_shipped_model(system: SystemFile) -> bool:
    """Whether the system flies the shipped network on the shipped classes (the exact default path)."""
    from el.labels import UAVID

    return (system_build.model_kind(system) == "builtin" and not system.get("model.class_map")
            and system_build.label_set(system) == UAVID)


def model_spec(args: argparse.Namespace) -> Any:
    """What a campaign records and its workers load: the ``--model`` given, else the system's model (None for
    the shipped one, else its source as data, ``assurance.system.build.model_source``)."""
    given = getattr(args, "weights", None)
    if given is not None:
        return given
    system = system_of(args)
    return None if is_shipped_model(system) else system_build.model_source(system)


def load_model(args: argparse.Namespace, *, threads: int | None = None, working_width: int | None = None) -> Any:
    """The segmentation model of the command: ``--model`` if given, else the system file's."""
    from assurance.system.model import load_model_spec

    return load_model_spec(model_spec(args), threads=threads, working_width=working_width)


def frame_gate_path(args: argparse.Namespace) -> Path | None:
    """The command's frame gate: ``--gate``, else the system file's ``[monitor] gate`` (``none``: no gate), else the
    shipped gate (``el.pipeline.DEPLOYED_GATE``, None when none is deployed) when the command runs the shipped
    network: a gate is bound to its network, so another network needs its own (``uav-el fit-gate``)."""
    from el.pipeline import DEPLOYED_GATE

    system = system_of(args)
    given = getattr(args, "gate", None)
    value = given if given is not None else system.get("monitor.gate")
    if value is not None:
        return None if str(value) == "none" else Path(given) if given is not None else system.path_of("monitor.gate")
    return DEPLOYED_GATE if model_spec(args) is None else None
