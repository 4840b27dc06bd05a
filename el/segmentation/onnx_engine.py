"""ONNX Runtime under the flight code: opening a checked session, and the engine of a project network.

Two users. :mod:`el.segmentation.onnx_model` runs a network from elsewhere (a user's ``.onnx`` file);
:class:`el.segmentation.inference.Segmenter` runs the shipped network's frames and HD patches through
the ONNX export committed beside its weights (docs/architecture.md section 3.2), with torch as the
fallback. ``onnxruntime`` is an optional extra, imported only here and only when used.

The engine of a weights file ``NAME.pt`` is ``NAME.onnx`` with its record ``NAME.onnx.json``
(``{"format", "weights_sha256", "onnx_sha256", "opset"}``, written by ``uav-el export-onnx --beside``): it is used
only when the record names the weights' SHA-256 (the card's) and the ONNX file has the SHA-256 the record
names. The environment variable ``UAV_EL_ENGINE`` chooses: ``auto`` (default: ONNX Runtime when installed
and the checked file is there, else torch), ``torch``, or ``onnx`` (ONNX Runtime or a ``WeightsError``).
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from el.errors import WeightsError
from el.hashing import sha256_bytes

ENGINE_ENV = "UAV_EL_ENGINE"
ENGINES = ("auto", "torch", "onnx")
RECORD_FORMAT = "uav-el-onnx-engine/1"
logger = logging.getLogger(__name__)
MISSING = "ONNX models need onnxruntime: pip install 'uav-el-assurance[onnx]'"


def onnxruntime() -> Any:
    """The ``onnxruntime`` module, or a one-line ``WeightsError`` saying how to install it."""
    try:
        import onnxruntime as ort
    except ImportError:
        raise WeightsError(MISSING) from None
    return ort


def have_onnxruntime() -> bool:
    """Whether ONNX Runtime can be imported (without importing it twice)."""
    try:
        onnxruntime()
    except WeightsError:
        return False
    return True


def read_checked(path: str | Path, sha256: str | None = None) -> tuple[bytes, str]:
    """The bytes of an ONNX file and their SHA-256; ``WeightsError`` naming the file (and both hashes)."""
    p = Path(path)
    if not p.is_file():
        raise WeightsError(f"{p}: ONNX file not found")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise WeightsError(f"{p}: cannot read the ONNX file: {exc}") from None
    digest = sha256_bytes(data)
    if sha256 is not None and digest != sha256:
        raise WeightsError(f"{p}: SHA-256 mismatch: file has {digest}, expected {sha256}")
    return data, digest


def open_session(data: bytes, where: str | Path, threads: int | None = None) -> Any:
    """A CPU ``InferenceSession`` on the model bytes (checked before, never re-read from disk).

    ``threads``: intra-op threads (None: ONNX Runtime's default); graph optimisations on, one inter-op
    thread, sequential execution, so runs of one session are reproducible."""
    ort = onnxruntime()
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    options = ort.SessionOptions()
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.inter_op_num_threads = 1
    if threads is not None:
        options.intra_op_num_threads = threads
    options.log_severity_level = 3  # errors only: the fault path reports them
    try:
        return ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own classes for a malformed graph
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise WeightsError(f"{where}: ONNX Runtime cannot load the model: {first}") from None


def metadata(session: Any) -> dict[str, str]:
    """The model's ``metadata_props`` (key -> string)."""
    return dict(session.get_modelmeta().custom_metadata_map)


def engine_choice() -> str:
    """The engine ``UAV_EL_ENGINE`` asks for (``auto`` when unset); a ValueError for anything else."""
    value = os.environ.get(ENGINE_ENV, "auto").strip().lower() or "auto"
    if value not in ENGINES:
        raise WeightsError(f"{ENGINE_ENV}={value!r}: expected one of {', '.join(ENGINES)}")
    return value


def record_path(weights_path: str | Path) -> Path:
    """The engine record of a weights file: ``NAME.onnx.json``."""
    return Path(weights_path).with_suffix(".onnx.json")


def engine_record(weights_sha256: str, onnx_sha256: str, opset: int) -> dict[str, Any]:
    """The record binding an ONNX export to the weights it was exported from."""
    return {"format": RECORD_FORMAT, "weights_sha256": weights_sha256, "onnx_sha256": onnx_sha256,
            "opset": int(opset)}


class OnnxEngine:
    """The logits of a project network under ONNX Runtime: float32 NCHW RGB in [0, 1] -> (B, C, H, W).

    Picklable (worker processes): the session is opened again from the checked file's bytes."""

    def __init__(self, path: str | Path, sha256: str, threads: int | None = None) -> None:
        self.path, self.sha256, self.threads = str(path), sha256, threads
        data, _ = read_checked(path, sha256)
        self._session = open_session(data, path, threads)
        self._input = self._session.get_inputs()[0].name

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "sha256": self.sha256, "threads": self.threads}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"], state["sha256"], state["threads"])  # type: ignore[misc]

    def logits(self, batch: np.ndarray) -> np.ndarray:
        """Logits of a (B, 3, H, W) float32 batch."""
        return self._session.run(None, {self._input: np.ascontiguousarray(batch, np.float32)})[0]


def engine_for(weights_path: str | Path, weights_sha256: str | None, threads: int | None = None
               ) -> OnnxEngine | None:
    """The ONNX Runtime engine of a weights file, or None for torch (see the module docstring).

    ``auto``: a missing, stale or altered export falls back to torch (the reference) with a warning;
    ``onnx``: it is a ``WeightsError``."""
    choice = engine_choice()
    if choice == "torch":
        return None
    if choice == "auto" and not (record_path(weights_path).is_file() and have_onnxruntime()):
        return None
    try:
        return _checked_engine(weights_path, weights_sha256, threads)
    except WeightsError as exc:
        if choice == "onnx":
            raise
        logger.warning("ONNX engine not used, torch runs the network: %s", exc)
        return None


def _checked_engine(weights_path: str | Path, weights_sha256: str | None, threads: int | None) -> OnnxEngine:
    rec_path = record_path(weights_path)
    onnx_path = Path(weights_path).with_suffix(".onnx")
    try:
        record = json.loads(rec_path.read_text(encoding="utf-8"))
        if not isinstance(record, dict) or record.get("format") != RECORD_FORMAT:
            raise ValueError(f"not a {RECORD_FORMAT} record")
        bound, onnx_sha = record["weights_sha256"], record["onnx_sha256"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise WeightsError(f"{rec_path}: unusable ONNX engine record ({exc})") from None
    if weights_sha256 is None or bound != weights_sha256:
        raise WeightsError(f"{rec_path}: records weights {bound}, the network is {weights_sha256} "
                           f"(export it again: uav-el export-onnx --beside)")
    return OnnxEngine(onnx_path, onnx_sha, threads)
