"""The identity of a campaign run (its manifest): configuration, data, network, fitted monitor models, code.

A resumed run must match it, the requirement checks read it, and the evidence report shows it.
"""

from __future__ import annotations

import hashlib
import os
import platform
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from assurance.campaign import readouts
from assurance.campaign.model_files import model_files
from assurance.campaign.perturbation_plan import domain_record
from assurance.code_identity import code_identity
from assurance.dataio.poses import read_meta
from el.base import torch_extra
from el.base.hashing import sha256_file
from el.classes.labels import LabelSet
from el.monitors import build_monitor
from el.monitors.capabilities import check_monitor_capabilities
from el.segmentation.contract import labels_of, weights_sha256_of
from el.segmentation.factory import FILE, PLUGIN, is_onnx_file, model_kind
from el.segmentation.onnx_engine import file_identity
from el.segmentation.protocol import FRAME_OPTIONS, card_protocol
from el.segmentation.weights import DEFAULT_WEIGHTS, read_card

NOT_INSTALLED = "not installed"

if TYPE_CHECKING:
    from assurance.campaign.run import CampaignConfig, Task


def manifest(data: str | Path, config: CampaignConfig, tasks: Sequence[Task], *, threads: int | None = None,
             segmenter: str = "weights", model: Any = None, system: Mapping[str, Any] | None = None,
             labels: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Identity of a campaign: config, seeds, versions, git commit, hashes of weights and data.

    ``threads`` (torch threads per worker) is recorded because floating-point sums, hence the
    readouts' last digits, depend on it: a re-run reproduces the readouts with the same count.
    ``model``: the loaded model, for the weights hash a model registered by name reports. ``system``: the
    record of the system file the campaign assesses (``SystemFile.record()``). ``labels``: the content hashes of the
    label set and class hierarchy the readouts are judged with (``assurance.campaign.label_pin.flown_labels``).
    """
    weights_record = _weights_record(config.weights, model)
    return {
        "format": readouts.FORMAT_VERSION,
        "config": config.to_dict(),
        "data": {"path": str(Path(data).resolve()), "images": len({t.sample.key for t in tasks}),
                 "sha256": data_sha256(data, tasks), "splits": scene_splits(tasks), **_data_spec(data)},
        "weights": weights_record,
        "monitor_models": monitor_models(config.monitors, labels_of(model)),
        "model_files": model_files(weights_record, config.monitors, labels_of(model)),
        **_perturbation_domain(config),
        "tasks": len(tasks),
        "integrity": readouts.INTEGRITY,
        "shard_order": [t.shard_name for t in tasks],
        "threads_per_worker": threads,
        "segmenter": segmenter,
        **({"system": dict(system)} if system is not None else {}),
        **({"labels": dict(labels)} if labels is not None else {}),
        "code": code_identity(),
        "versions": {"python": sys.version.split()[0], "numpy": np.__version__,
                     "torch": torch_version(), "onnxruntime": _dist_version("onnxruntime"),
                     "platform": platform.platform(), "instruction_set": instruction_set()},
    }


def data_sha256(data: str | Path, tasks: Sequence[Task]) -> str:
    """The hash of a campaign's data: each image, label and per-frame file its tasks read, by its path relative to
    the data folder (what a re-run compares, ``assurance.requirements.determinism``)."""
    files = sorted({t.sample.image_path for t in tasks} | {t.sample.label_path for t in tasks if t.sample.label_path}
                   | _frame_files(tasks))
    h = hashlib.sha256()
    root = os.path.normpath(os.fspath(data))  # a [data] path holding ".." is spelled as the files found under it
    for f in files:
        h.update(f"{Path(os.path.relpath(os.path.normpath(f), root)).as_posix()}:{sha256_file(f)}\n".encode())
    return h.hexdigest()


def instruction_set(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """The widest vector instruction set the CPU offers ONNX Runtime's kernels: ``avx512``, ``avx2``, ``x86-64``,
    else the machine name (``aarch64``, ...). Kernels chosen per instruction set differ in their last bits, so a
    release run's headline is recorded per instruction set (``assurance.analysis.headline``)."""
    machine = platform.machine().lower()
    if machine not in ("x86_64", "amd64"):
        return {"arm64": "aarch64"}.get(machine, machine) or "unknown"  # one CPU family, two names
    try:
        text = Path(cpuinfo).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return "x86-64"
    flags = set()
    for line in text.splitlines():
        if line.startswith("flags"):
            flags = set(line.partition(":")[2].split())
            break
    return "avx512" if "avx512f" in flags else "avx2" if "avx2" in flags else "x86-64"


def _perturbation_domain(config: CampaignConfig) -> dict[str, Any]:
    """``perturbation_domain``: whether each perturbation ran inside the declared domain
    (``assurance.campaign.perturbation_plan.domain_record``); nothing for a run that declares none."""
    record = domain_record(config.perturbations, config.scenarios(), config.odd)
    return {} if record is None else {"perturbation_domain": record}


def _data_spec(data: Any) -> dict[str, Any]:
    """``{"spec": ...}`` for data read through a ``[data]`` table (``assurance.dataio.layouts.DataSpec``, its root
    resolved): what re-reads the run's frames (``layouts.data_source``); nothing for a folder, read as before."""
    to_dict = getattr(data, "to_dict", None)
    return {} if to_dict is None else {"spec": {**to_dict(), "path": str(Path(data).resolve())}}


def torch_version() -> str:
    """torch's version, or ``not installed`` (a base install runs the shipped network on ONNX Runtime)."""
    if not torch_extra.have_torch():
        return NOT_INSTALLED
    import torch  # installed: the version the campaign ran with (it imported torch already)

    return str(torch.__version__)


def _dist_version(name: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return NOT_INSTALLED


def scene_splits(tasks: Sequence[Task]) -> dict[str, int]:
    """Frames per split their scene's ``meta/*.json`` declares (synthetic scenes; none for data without meta):
    EL-R16 judges a calibration card on the test split only."""
    out: dict[str, int] = {}
    for sample in {t.sample.key: t.sample for t in tasks}.values():
        path = sample.meta_path()
        try:  # bounded, as every scene meta file is read: a FIFO or a link to /proc is passed over
            split = read_meta(path).get("split") if path.is_file() else None
        except (OSError, ValueError):
            split = None
        if isinstance(split, str):
            out[split] = out.get(split, 0) + 1
    return dict(sorted(out.items()))


def _frame_files(tasks: Sequence[Task]) -> set[Path]:
    """The per-frame files besides image and labels that readouts rest on: a scene's meta (its pose, its world
    model: the clearance readouts) and a sequence's poses sidecar, whatever the pose policy."""
    out: set[Path] = set()
    for t in tasks:
        for path in (t.sample.meta_path(), t.sample.poses_path):
            if path is not None and path.is_file():
                out.add(path)
    return out


def check_monitor_networks(specs: Sequence[str], segmenter: Any) -> None:
    """Refuse, before any task, a configuration whose monitor was fitted on another network than the
    campaign's (the monitor's error: one line naming the file and both networks), or needs a capability the
    network lacks (``el.monitors.capabilities``: MC dropout on an ONNX file)."""
    for spec in specs:
        monitor = build_monitor(spec, labels=labels_of(segmenter))
        if monitor is not None:
            monitor.check_network(segmenter)
            check_monitor_capabilities(monitor, segmenter)


def monitor_models(specs: Sequence[str], labels: LabelSet) -> dict[str, str]:
    """SHA-256 of the fitted model file each configuration's scores rest on (learned monitors), by spec.

    Recorded in the manifest: a resumed run must score with the same models, and a calibration card
    is checked against the model the run used (EL-R16)."""
    out: dict[str, str] = {}
    for spec in specs:
        digest = getattr(build_monitor(spec, labels=labels), "model_sha256", None)
        if digest:
            out[spec] = digest
    return out


def _weights_record(spec: str | dict[str, Any] | None, model: Any) -> dict[str, Any]:
    """The manifest's ``weights``: path, SHA-256 and frame options of a weights file (the shipped one for
    None) and the engine that ran its full passes (``torch`` or ``onnx``); for an ONNX file, its path, its
    SHA-256 and its input contract; for a model registered by name, the name and the hash the model reports."""
    if spec is None and model is not None and not _is_shipped(model):  # a model object given through the API
        return {"path": None, "model": type(model).__name__, "sha256": weights_sha256_of(model),
                **dict.fromkeys(FRAME_OPTIONS)}
    if isinstance(spec, dict):  # a system file's model: its file (if any), kind and the hash the model reports
        return {"path": spec.get("path"), "model": spec.get("kind"), "sha256": weights_sha256_of(model),
                "class_map": spec.get("class_map"), **dict.fromkeys(FRAME_OPTIONS)}
    if model_kind(spec) == PLUGIN:
        return {"path": None, "model": spec, "sha256": weights_sha256_of(model), **dict.fromkeys(FRAME_OPTIONS)}
    if is_onnx_file(spec):
        contract = getattr(model, "contract", None)
        return {"path": str(spec), "sha256": file_identity(spec) if Path(spec).is_file() else None, "format": "onnx",
                "engine": "onnx", "contract": contract.to_dict() if contract is not None else None,
                **dict.fromkeys(FRAME_OPTIONS)}
    weights = Path(spec) if model_kind(spec) == FILE else DEFAULT_WEIGHTS
    record = {"path": str(weights), "sha256": sha256_file(weights) if weights.is_file() else None,
              **_frame_protocol(weights)}
    if model is not None:
        record["engine"] = getattr(model, "engine_name", None)
    return record


def _is_shipped(model: Any) -> bool:
    """Whether a model reports the shipped weights' hash (so the shipped file's record describes it)."""
    return DEFAULT_WEIGHTS.is_file() and weights_sha256_of(model) == sha256_file(DEFAULT_WEIGHTS)


def _frame_protocol(weights: Path) -> dict[str, Any]:
    """How the weights' card has frames segmented (``frame_flip``, ``frame_scales``); None without a card."""
    try:
        return card_protocol(read_card(weights)).frame_options()
    except (OSError, ValueError):  # WeightsError is a ValueError
        return dict.fromkeys(FRAME_OPTIONS)
