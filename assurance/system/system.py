"""The system under assessment, built once: every part its file declares (or the embedded default), checked together
before any work starts, and handed to every command and layer below the command line.

``System.build`` reads the file's sections through ``assurance.system.build`` (one function a section) and keeps the
results: the label set, the CM configuration (camera, nominal pose, safety), the declared operating domain, the pose
policy, the network (as data, ``model``; loaded by :meth:`System.segmenter`), the deployed monitor and its
calibration card, the frame gate, the time budget, the requirement targets, the waivers and the report settings.
The flight configuration (:meth:`System.flight_config`) and a campaign's (``assurance.campaign.presets``, from the
same fields) are both made from it, so what a campaign assesses is what flies.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from assurance.system import build
from assurance.system.loader import SystemFile, SystemFileError
from assurance.system.model import load_model_spec
from assurance.system.sense import gate_refusal
from el.base.deadline import DEFAULT_TIME_BUDGET_S
from el.base.errors import WeightsError
from el.classes.labels import UAVID, LabelSet
from el.geometry.config import CoreConfig
from el.geometry.odd import OperatingDomain
from el.monitors.calibration import load_calibration
from el.segmentation.onnx_engine import read_onnx, shipped_export_source

NO_GATE = "none"


@dataclass(frozen=True, kw_only=True)
class System:
    """One system under assessment (see the module docstring); build it with :meth:`build`.

    ``model``: the network as data (None: the shipped network on the shipped classes; else a model source,
    ``assurance.system.build.model_source``, or a ``--model`` given on the command line). ``monitor``: the
    deployed monitor's spec; ``calibration``: the card the file names (None: none; the shipped monitor is then held to
    the shipped card, ``el.flight.pipeline.check_monitor_bindings``). ``gate``: the frame gate file (None: no gate).
    """

    file: SystemFile
    labels: LabelSet
    core: CoreConfig
    odd: OperatingDomain
    poses: str
    model: Any
    monitor: str
    calibration: Path | None
    gate: Path | None
    budget_s: float | None
    targets: dict[str, Any] = field(default_factory=dict)
    waivers: str | None = None
    report: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def build(cls, file: SystemFile, *, model: Any = None, gate: str | Path | None = None,
              waivers: str | None = None) -> System:
        """The system of ``file``, with a command line's ``--model`` and ``--gate`` (``none``: no gate) winning.
        Every section is read and checked here (``SystemFileError`` naming the file and the key); the calibration
        card is read when the deployed pair is (:meth:`deployed`): ``uav-el calibrate`` may be about to write it. The
        frame gate it ends up with is checked for sense (``assurance.system.sense``), a ``--gate`` as a file's is."""
        labels = build.label_set(file)
        shipped = model is None and build.model_kind(file) == "builtin" and not file.get("model.class_map") \
            and labels == UAVID
        if model is None and not shipped:
            model = build.model_source(file)
        budget = file.get("targets.time_budget_s", DEFAULT_TIME_BUDGET_S)
        carries_shipped_gate = model is None or (labels == UAVID and _shipped_export(model))
        return cls(file=file, labels=labels, core=build.core_config(file), odd=build.odd(file),
                   poses=build.poses_policy(file), model=model, monitor=build.monitor_spec(file) or "",
                   calibration=file.path_of("monitor.calibration"),
                   gate=_checked_gate(file, gate, _gate(file, gate, shipped=carries_shipped_gate)),
                   budget_s=None if budget is None else float(budget), targets=build.targets(file),
                   waivers=build.waivers(file, waivers), report=build.report_settings(file))

    @property
    def shipped_network(self) -> bool:
        """Whether the system flies the shipped network on the shipped classes."""
        return self.model is None

    @property
    def label(self) -> str:
        """How messages name the system file."""
        return self.file.label

    def data(self, split: str, given: str | Path | None = None) -> Any:
        """The data set of ``split``: ``given``, else the file's ``[data] <split>``, a folder or a table (a ``Path``
        or an ``assurance.dataio.layouts.DataSpec``, both path-like; a clear error when neither)."""
        return build.data_root(self.file, split, given)

    def segmenter(self, *, threads: int | None = None, working_width: int | None = None) -> Any:
        """The system's network, loaded (a ``WeightsError`` naming the file when it cannot be)."""
        return load_model_spec(self.model, threads=threads, working_width=working_width)

    def deployed(self) -> tuple[str, Path | None]:
        """The deployed monitor's spec and its card, checked together (``SystemFileError`` for a spec off its card's
        threshold); a file naming only a card deploys the card's own monitor."""
        build.check_deployed_calibration(self.file)
        if self.calibration is not None and not self.file.sets("monitor.spec"):
            return load_calibration(self.calibration).monitor, self.calibration
        return self.monitor, self.calibration

    def flight_config(self, **overrides: Any) -> Any:
        """The flight configuration of the deployed system (``el.flight.pipeline.PipelineConfig``): its CM
        configuration,
        monitor at its card's threshold, frame gate, declared domain and time budget; ``overrides`` win."""
        from el.flight.pipeline import PipelineConfig  # deferred: pulls in scipy; keeps the commands' --help light

        monitor, card = self.deployed()
        values: dict[str, Any] = {"core": self.core, "monitor": monitor or None,
                                  "calibration": None if card is None else str(card),
                                  "gate": None if self.gate is None else str(self.gate), "odd": self.odd,
                                  "time_budget_s": self.budget_s}
        values.update(overrides)
        return PipelineConfig(**values)


def _gate(file: SystemFile, given: str | Path | None, *, shipped: bool) -> Path | None:
    """The frame gate: ``given`` (a command line's ``--gate``), else ``[monitor] gate`` (``none``: no gate), else
    the shipped gate (``el.flight.pipeline.DEPLOYED_GATE``) on the shipped network: a gate is bound to its network, so
    another network needs its own (``uav-el fit-gate``)."""
    from el.flight.pipeline import DEPLOYED_GATE  # deferred: pulls in scipy; keeps the commands' --help light

    if given is not None:
        return None if str(given) == NO_GATE else Path(given)
    value = file.get("monitor.gate")
    if value is not None:
        return None if str(value) == NO_GATE else file.path_of("monitor.gate")
    return DEPLOYED_GATE if shipped else None


def _shipped_export(model: Any) -> bool:
    """Whether a system file's model is the shipped network's packaged ONNX export (the very file, by its SHA-256,
    as the package's engine record names it) with no class map: on the shipped classes it carries the shipped frame
    gate."""
    if not isinstance(model, dict) or model.get("kind") != "onnx" or model.get("class_map") or model.get("classes"):
        return False
    path = model.get("path")
    if not path or not os.path.isfile(path):
        return False  # a FIFO or a device is not hashed here: its loader names the problem
    try:
        found = read_onnx(path)  # read once: the network's loader takes these very bytes
    except WeightsError:
        return False  # its loader names the problem
    return not found.external and shipped_export_source(found.sha256) is not None


def _checked_gate(file: SystemFile, given: str | Path | None, gate: Path | None) -> Path | None:
    """``gate`` (the frame gate the system ends up with), refused (``SystemFileError`` naming the gate file) when it
    makes no sense (``assurance.system.sense.gate_problem``: its threshold outside the scores it was fitted on) or
    cannot be read (a FIFO, a device: the bounded reader's line). The system file's gate was checked when the file
    was loaded; a ``--gate`` (``given``) had no such check, so a re-hashed gate passing every frame flew. A path
    with nothing at it is left to the command that loads the gate, whose loader names it (one line, exit 2)."""
    if gate is None or not os.path.lexists(gate):
        return gate
    why = gate_refusal(gate)
    if why:
        if given is not None:
            raise SystemFileError(f"--gate {why}")  # why opens with the gate file's path
        raise file.error("monitor.gate", why) if file.get("monitor.gate") is not None else SystemFileError(why)
    return gate


__all__ = ["NO_GATE", "System"]
