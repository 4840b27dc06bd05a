"""The model files a run's decisions rest on, by SHA-256: recorded in the (signed) manifest, re-checked by the gate.

A network's weights and card, the learned monitors' model files, and the packaged models and cards (the shipped
network, the learned monitor, the calibration card, the out-of-domain gate). Each self-hashed file only proves it
was not damaged; re-hashing one after an edit (a monitor made to accept everything) hides the edit from the file
itself, not from the run's signed record: ``changed_model_files`` names every file that differs now.

Every file is hashed through the bounded reader (``el.base.userfiles``, at most ``MAX_MODEL_BYTES``, in chunks): a
manifest entry the applicant wrote (and re-signed) naming ``/proc/self/pagemap``, a FIFO or a device is a problem
naming it, never a read that does not end.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from assurance.code_identity import install_root
from el.base.errors import WeightsError
from el.base.hashing import sha256_file
from el.base.userfiles import MAX_MODEL_BYTES, UserFileError
from el.classes.labels import LabelSet
from el.monitors import build_monitor
from el.segmentation.onnx_engine import external_files

PACKAGED = ("el/monitors/data", "el/segmentation/weights")
"""Folders (under the install root) of the packaged models and their cards."""
SUFFIXES = (".json", ".pt", ".onnx")


def _label(path: Path) -> str:
    """A packaged file by its path in the package (so an auditor's installation is checked), others absolute."""
    path = path.resolve()
    try:
        return path.relative_to(install_root()).as_posix()
    except ValueError:
        return str(path)


def _resolve(label: str) -> Path:
    p = Path(label)
    return p if p.is_absolute() else install_root() / p


def _monitor_files(specs: Sequence[str], labels: LabelSet) -> Iterable[Path]:
    for spec in specs:
        model = getattr(build_monitor(spec, labels=labels), "model", None)
        path = getattr(model, "path", None)
        if path:
            yield Path(path)


def _external_data(path: Path) -> list[Path]:
    """An ONNX file's external data files (each is recorded and re-checked like the file itself)."""
    if path.suffix.lower() != ".onnx" or not path.is_file():
        return []
    try:
        return external_files(path)
    except WeightsError:  # unreadable external data: the model did not load, nothing ran on it
        return []


def model_files(weights: Mapping[str, Any] | None, monitors: Sequence[str], labels: LabelSet) -> dict[str, str]:
    """``{file: SHA-256}`` of the run's weights file (and its card), its monitors' model files and the packaged
    models and cards, for the manifest."""
    paths: list[Path] = []
    w = (weights or {}).get("path")
    if w:
        paths += [Path(w), Path(w).with_suffix(".json"), Path(f"{w}.json"), *_external_data(Path(w))]
    paths += list(_monitor_files(monitors, labels))
    root = install_root()
    for folder in PACKAGED:
        d = root / folder
        if d.is_dir():
            paths += [p for p in d.iterdir() if p.suffix in SUFFIXES]
    return {_label(p): sha256_file(p, what="model file", max_bytes=MAX_MODEL_BYTES)
            for p in sorted(set(paths)) if p.is_file()}


def changed_model_files(recorded: Mapping[str, str] | None) -> tuple[list[str], list[str]]:
    """(problems, unchecked): a recorded model file that differs now, one line each naming it and both hashes, or
    one that cannot be a model file (a FIFO, a device, a path under ``/proc``, ``/sys`` or ``/dev``, a file over
    ``MAX_MODEL_BYTES``: refused unread, named); the files not found here (an auditor without the user's weights),
    which cannot be checked."""
    problems, unchecked = [], []
    for label, digest in sorted((recorded or {}).items()):
        path = _resolve(label)
        try:
            now = sha256_file(path, what="model file", max_bytes=MAX_MODEL_BYTES)
        except FileNotFoundError:
            unchecked.append(label)
            continue
        except (OSError, UserFileError) as exc:
            why = str(exc) if isinstance(exc, UserFileError) else str(exc.strerror or exc)
            why = why.removeprefix(f"{path}: ")  # the refusal names the file: the line does already
            problems.append(f"{label}: a model file the run records, refused unread ({why}); the run's evidence "
                            "cannot be shown to be about the file it names")
            continue
        if now != digest:
            problems.append(f"{label}: changed since the run was made (SHA-256 {digest[:12]} then, {now[:12]} now): "
                            "the run's evidence is about the file as it was; re-run the campaign")
    return problems, unchecked
