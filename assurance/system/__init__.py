"""The system under assessment, as one file (``uav-el.toml``): model, camera, poses, label set, safety radius,
monitor, data, targets, waivers and report (docs/architecture.md, "The system file").

``find_system(path)`` reads ``--system FILE``, else ``uav-el.toml`` in the working directory, else the embedded
default (the shipped system); ``assurance.system.build`` turns its sections into the objects the commands take.
"""

from __future__ import annotations

from assurance.system.find import find_system, load_system
from assurance.system.loader import FORMAT, SYSTEM_FILE, SystemFile, SystemFileError, default_system, schema

__all__ = ["FORMAT", "SYSTEM_FILE", "SystemFile", "SystemFileError", "default_system", "find_system",
           "load_system", "schema"]
