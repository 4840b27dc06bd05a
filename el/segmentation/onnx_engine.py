"""ONNX Runtime under the flight code: opening a checked session, and the engine of a project network.

Two users. :mod:`el.segmentation.onnx_model` runs a network from elsewhere (a user's ``.onnx`` file);
:class:`el.segmentation.inference.Segmenter` runs the shipped network's frames and HD patches through
the ONNX export committed beside its weights (docs/architecture.md section 3.2), with torch as the
fallback. ``onnxruntime`` is an optional extra, imported only here and only when used.

Every ONNX file is read once and checked here (:func:`read_onnx`): its external data files, if any, must lie
in the model file's folder, are hashed into its identity (:func:`external_identity`) and are copied into the
model before ONNX Runtime sees it, so no file is read after the check and the working directory plays no part.

The engine of a weights file ``NAME.pt`` is ``NAME.onnx`` with its record ``NAME.onnx.json``
(``{"format", "weights_sha256", "onnx_sha256", "opset"}``, written by ``uav-el export-onnx --beside``): it is used
only when the record names the weights' SHA-256 (the card's) and the ONNX file has the SHA-256 the record
names. The environment variable ``UAV_EL_ENGINE`` chooses: ``auto`` (default: ONNX Runtime when installed
and the checked file is there, else torch), ``torch``, or ``onnx`` (ONNX Runtime or a ``WeightsError``).
"""

from __future__ import annotations

import functools
import json
import logging
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from el.base import userfiles
from el.base.deadline import stop_at_deadline
from el.base.errors import BudgetExceeded, WeightsError
from el.base.hashing import sha256_bytes, sha256_file

ENGINE_ENV = "UAV_EL_ENGINE"
ENGINES = ("auto", "torch", "onnx")
RECORD_FORMAT = "uav-el-onnx-engine/1"
logger = logging.getLogger(__name__)
MISSING = "ONNX models need onnxruntime: pip install 'uav-el-assurance[onnx]'"
EXTERNAL_FORMAT = "uav-el-onnx-external/1"
EXTERNAL_KEY = b"location"
SHIPPED_DIR = Path(__file__).resolve().parent / "weights"  # the package's own weights, card and export record


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
    """The model bytes ONNX Runtime is given (external data read, confined and inlined) and the file's identity
    (:func:`read_onnx`); ``WeightsError`` naming the file (and both identities)."""
    found = read_onnx(path)
    if sha256 is not None and found.sha256 != sha256:
        raise WeightsError(f"{path}: SHA-256 mismatch: file has {found.sha256}, expected {sha256}")
    return found.data, found.sha256


@dataclass(frozen=True)
class OnnxFile:
    """An ONNX file read once: ``data``, the bytes a session is built from (no external reference left);
    ``sha256``, its identity (:func:`read_onnx`); ``external``, each external data file (path relative to the
    model's folder) -> its SHA-256 (empty for a self-contained file)."""

    data: bytes
    sha256: str
    external: dict[str, str]


def read_onnx(path: str | Path) -> OnnxFile:
    """Read an ONNX file and the external data it names, checked; every problem a one-line ``WeightsError``.

    External data (tensors whose bytes lie in other files, ``location`` in the tensor's ``external_data``) are
    resolved relative to the model file's folder and must stay inside it: an absolute location, a ``..`` or a
    symbolic link leading out of the folder is refused, naming the model file and the location. Each external
    file is read once and its bytes are copied into the tensors, so the session never reads a file itself.
    The identity is the file's plain SHA-256 when it has no external data (so existing pins hold), else
    :func:`external_identity` over the file and its external files."""
    p = Path(path)
    if not p.is_file():
        raise WeightsError(f"{p}: ONNX file not found")

    try:  # bounded: never under /proc, /sys or /dev, at most MAX_MODEL_BYTES
        data = userfiles.read_bytes(p, what="ONNX file", max_bytes=userfiles.MAX_MODEL_BYTES, hard_links=True)
    except userfiles.UserFileError as exc:
        raise WeightsError(str(exc)) from None
    digest = sha256_bytes(data)
    if EXTERNAL_KEY not in data:  # no tensor can name an external file without a "location" entry
        return OnnxFile(data, digest, {})
    proto, tensors = _external_tensors(data, p)
    if not tensors:
        return OnnxFile(data, digest, {})
    blobs: dict[str, bytes] = {}
    for tensor in tensors:
        _inline(tensor, p, blobs)
    try:
        inlined = proto.SerializeToString()
    except Exception as exc:  # protobuf refuses a message over 2 GiB
        raise WeightsError(f"{p}: the model with its external data inlined cannot be serialised "
                           f"({type(exc).__name__}: {exc}); ONNX models over 2 GiB are not supported") from None
    external = {rel: sha256_bytes(blob) for rel, blob in blobs.items()}
    return OnnxFile(inlined, external_identity(digest, external), external)


def external_identity(onnx_sha256: str, external: dict[str, str]) -> str:
    """The identity of an ONNX file with external data: the SHA-256 of the canonical listing
    ``uav-el-onnx-external/1``, ``onnx <file SHA-256>``, then ``data <SHA-256> <path>`` for each external file
    (path relative to the model's folder, ``/``-separated, sorted), one line each, newline-terminated."""
    lines = [EXTERNAL_FORMAT, f"onnx {onnx_sha256}"] + [f"data {external[r]} {r}" for r in sorted(external)]
    return sha256_bytes(("\n".join(lines) + "\n").encode("utf-8"))


def file_identity(path: str | Path) -> str:
    """The identity a weights file is pinned and recorded by: :func:`read_onnx`'s for an ``.onnx`` file (its
    external data included), the plain SHA-256 otherwise; ``WeightsError`` for an ONNX file that cannot be read."""
    if str(path).lower().endswith(".onnx"):
        return read_onnx(path).sha256

    return sha256_file(path)


def external_files(path: str | Path) -> list[Path]:
    """The external data files of an ONNX file (checked as :func:`read_onnx` does), for a run's model files."""
    folder = Path(path).parent
    return [folder / rel for rel in sorted(read_onnx(path).external)]


def _onnx_module() -> Any:
    try:
        import onnx
    except ImportError:
        raise WeightsError("an ONNX file with external data needs the onnx package: "
                           "pip install 'uav-el-assurance[onnx]'") from None
    return onnx


def _external_tensors(data: bytes, where: Path) -> tuple[Any, list[Any]]:
    """The parsed model and every tensor in it (initialisers, node attributes, subgraphs, functions, sparse
    tensors' parts: found by walking the whole message) stored as external data."""
    onnx = _onnx_module()
    from google.protobuf.message import Message

    proto = onnx.ModelProto()
    try:
        proto.ParseFromString(data)
    except Exception as exc:  # a file that is not a serialised ModelProto
        raise WeightsError(f"{where}: not an ONNX model ({type(exc).__name__}: {exc})") from None
    found, stack = [], [proto]
    while stack:
        message = stack.pop()
        if isinstance(message, onnx.TensorProto):
            if message.data_location == onnx.TensorProto.EXTERNAL or len(message.external_data):
                found.append(message)
            continue
        for field, value in message.ListFields():
            if field.type == field.TYPE_MESSAGE:
                stack.extend([value] if isinstance(value, Message) else value)
    return proto, found


def _confined(model: Path, location: str) -> tuple[Path, str]:
    """The external file a location names and its path relative to the model's folder; ``WeightsError`` naming
    the model file and the location unless it is a file inside that folder."""
    from pathlib import PurePosixPath, PureWindowsPath

    def refuse(why: str) -> WeightsError:
        return WeightsError(f"{model}: external data location {location!r} refused: {why}")

    win = PureWindowsPath(location)
    if not location or PurePosixPath(location).is_absolute() or win.is_absolute() or win.drive or win.root:
        raise refuse("an absolute path (external data must lie in the model file's folder)")
    if ".." in win.parts or "\0" in location:
        raise refuse("it leads out of the model file's folder ('..')")
    folder = model.parent.resolve()
    target = (folder / location).resolve()
    if not target.is_relative_to(folder):
        raise refuse(f"it resolves to {target}, outside the model file's folder {folder} (a symbolic link)")
    if not target.is_file():
        raise refuse("no such file in the model file's folder")
    return target, target.relative_to(folder).as_posix()


def _inline(tensor: Any, model: Path, blobs: dict[str, bytes]) -> None:
    """Copy a tensor's external bytes (offset, length) into it from its confined file (read once into ``blobs``)."""
    info = {e.key: e.value for e in tensor.external_data}
    location = info.get("location", "")
    target, rel = _confined(model, location)
    if rel not in blobs:
        try:  # bounded, and confined to the model's folder (``_confined`` checked the name; this what it opens)
            blobs[rel] = userfiles.read_bytes(target, what="external data file", max_bytes=userfiles.MAX_MODEL_BYTES,
                                              within=model.parent, hard_links=True)
        except userfiles.UserFileError as exc:
            raise WeightsError(f"{model}: external data location {location!r}: cannot read it: {exc}") from None
    blob = blobs[rel]
    try:
        offset = int(info.get("offset", 0))
        length = int(info["length"]) if "length" in info else len(blob) - offset
    except ValueError:
        raise WeightsError(f"{model}: tensor {tensor.name!r}: external data offset/length are not integers "
                           f"({info.get('offset')!r}, {info.get('length')!r})") from None
    if offset < 0 or length < 0 or offset + length > len(blob):
        raise WeightsError(f"{model}: tensor {tensor.name!r}: external data {offset}+{length} bytes lie beyond "
                           f"the end of {location!r} ({len(blob)} bytes)")
    tensor.raw_data = blob[offset: offset + length]
    del tensor.external_data[:]
    tensor.data_location = type(tensor).DEFAULT


SESSION_CONFIG = {
    # no spin-waiting after a run: a spinning frame-session thread competes with the HD patch workers on 2 cores
    # (benchmarks/bench_stages.py --no-spinning measured the deployed decision 0.44 -> 0.35 s wall, same decisions)
    "session.intra_op.allow_spinning": "0",
}
"""The session configuration entries every session gets (``SessionOptions.add_session_config_entry``)."""
GRAPH_OPTIMIZATION = "ORT_ENABLE_ALL"
"""The graph optimisation level of every session, pinned rather than left to ONNX Runtime's default. Its layout
optimisation runs convolutions in MLAS's blocked (NCHWc) format, whose block and kernels are chosen per CPU
(AVX2 or AVX-512): the logits differ in their last bits between such CPUs, and between levels on one CPU (up to
1.2e-5 on a frame of the shipped network; docs/results.md, "Reproducibility across machines"), and no deployed
decision changed with them (90 frames: 30 test scenes clean, brightened and fogged, under ``ORT_DISABLE_ALL``). The
thread count changes no bit (1 and 2 intra-op threads give identical logits), so it is left to the caller."""


def session_options(threads: int | None = None) -> Any:
    """The ``SessionOptions`` every session is opened with: sequential execution, one inter-op thread, the graph
    optimisation level :data:`GRAPH_OPTIMIZATION`, the entries of :data:`SESSION_CONFIG`, errors-only logging, and
    ``threads`` intra-op threads (None: ONNX Runtime's default, one per physical core)."""
    ort = onnxruntime()
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    options = ort.SessionOptions()
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.inter_op_num_threads = 1
    options.graph_optimization_level = getattr(ort.GraphOptimizationLevel, GRAPH_OPTIMIZATION)
    if threads is not None:
        options.intra_op_num_threads = threads
    options.log_severity_level = 3  # errors only: the fault path reports them
    for key, value in SESSION_CONFIG.items():
        options.add_session_config_entry(key, value)
    return options


def open_session(data: bytes, where: str | Path, threads: int | None = None) -> Any:
    """A CPU ``InferenceSession`` on the model bytes (checked before, never re-read from disk), opened with
    :func:`session_options` (``threads``: intra-op threads, None for ONNX Runtime's default), so runs of one
    session, and sessions with any thread count, give the same numbers on one CPU."""
    ort = onnxruntime()
    options = session_options(threads)
    try:
        return ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises its own classes for a malformed graph
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise WeightsError(f"{where}: ONNX Runtime cannot load the model: {first}") from None


def run_session(session: Any, names: list[str], feeds: dict[str, Any], where: str) -> list[Any]:
    """``session.run(names, feeds)``, cancelled at the decision's deadline (no work goes on after the answer).

    Inside a decision (an active ``el.base.deadline`` deadline) the run gets its own ``RunOptions``, whose ``terminate``
    the deadline sets from another thread when it passes or is cancelled (:func:`el.base.deadline.stop_at_deadline`):
    ONNX Runtime then abandons the run at its next operator and this raises ``BudgetExceeded`` (the decision is
    ``timeout``), instead of computing on for a decision already returned. A run that ends before the deadline is
    the plain run (options change no number); outside a decision (campaigns, probes) nothing is armed."""
    options = onnxruntime().RunOptions()
    stopped = threading.Event()

    def stop() -> None:  # the deadline's timer thread, or the hard stop's
        stopped.set()
        options.terminate = True

    with stop_at_deadline(stop, where) as armed:
        try:
            return session.run(names, feeds, options) if armed else session.run(names, feeds)
        except Exception:
            if stopped.is_set():
                raise BudgetExceeded(f"ONNX Runtime run cancelled at the decision's deadline during {where}") from None
            raise


def metadata(session: Any) -> dict[str, str]:
    """The model's ``metadata_props`` (key -> string)."""
    return dict(session.get_modelmeta().custom_metadata_map)


def engine_choice() -> str:
    """The engine ``UAV_EL_ENGINE`` asks for (``auto`` when unset); a ``WeightsError`` for anything else."""
    value = os.environ.get(ENGINE_ENV, "auto").strip().lower() or "auto"
    if value not in ENGINES:
        raise WeightsError(f"{ENGINE_ENV}={value!r}: expected one of {', '.join(ENGINES)}")
    return value


def record_path(weights_path: str | Path) -> Path:
    """The engine record of a weights file: ``NAME.onnx.json``."""
    return Path(weights_path).with_suffix(".onnx.json")


@functools.lru_cache(maxsize=8)
def shipped_export_source(onnx_sha256: str) -> str | None:
    """The shipped weights' SHA-256 when ``onnx_sha256`` is the identity of their packaged ONNX export, else None.

    Vouched for by the package's own files only (the engine record beside the shipped weights and their card),
    never by a record or metadata beside a user's file: a hash a file carries about itself proves nothing. This
    is what lets the shipped network run as a plain ``.onnx`` file keep the records fitted on it (the shipped
    frame gate, card and learned monitor)."""
    try:
        record = json.loads((SHIPPED_DIR / "model.onnx.json").read_text(encoding="utf-8"))
        card = json.loads((SHIPPED_DIR / "model.json").read_text(encoding="utf-8"))
        bound = record["weights_sha256"] if record.get("format") == RECORD_FORMAT else None
        same = record["onnx_sha256"] == onnx_sha256 and bound == card["weights_sha256"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return bound if same and isinstance(bound, str) else None


def engine_record(weights_sha256: str, onnx_sha256: str, opset: int) -> dict[str, Any]:
    """The record binding an ONNX export to the weights it was exported from."""
    return {"format": RECORD_FORMAT, "weights_sha256": weights_sha256, "onnx_sha256": onnx_sha256,
            "opset": int(opset)}


def flatten_features(features: Any) -> tuple[list[str], list[Any]]:
    """A trunk's output (a dataclass such as ``LiteFeatures``) as named tensors: each tensor field, and each
    tensor of a tuple field (``trunk.levels.0``, ...), in field order; ``size`` is not a tensor and is left out."""
    import dataclasses

    names, tensors = [], []
    for f in dataclasses.fields(features):
        value = getattr(features, f.name)
        if isinstance(value, tuple) and value and all(hasattr(v, "shape") for v in value):
            names += [f"trunk.{f.name}.{i}" for i in range(len(value))]
            tensors += list(value)
        elif hasattr(value, "shape"):
            names.append(f"trunk.{f.name}")
            tensors.append(value)
    return names, tensors


def unflatten_features(template: Any, names: list[str], tensors: list[Any], size: tuple[int, int]) -> Any:
    """The trunk's output rebuilt from :func:`flatten_features`' tensors, like ``template`` (same type and fields)."""
    import dataclasses

    by_name = dict(zip(names, tensors, strict=True))
    values = {}
    for f in dataclasses.fields(template):
        value = getattr(template, f.name)
        if f.name == "size":
            values[f.name] = size
        elif isinstance(value, tuple):
            values[f.name] = tuple(by_name[f"trunk.{f.name}.{i}"] for i in range(len(value)))
        else:
            values[f.name] = by_name[f"trunk.{f.name}"] if f"trunk.{f.name}" in by_name else value
    return type(template)(**values)


class OnnxEngine:
    """The logits of a project network under ONNX Runtime: float32 NCHW RGB in [0, 1] -> (B, C, H, W), and the
    trunk outputs an export of a trunk/head network carries (:attr:`trunk_names`).

    Picklable (worker processes): the session is opened again from the checked file's bytes. ``data``: those bytes
    already read and checked (:meth:`sibling`), so a second session of the same network does not read it again."""

    def __init__(self, path: str | Path, sha256: str, threads: int | None = None, *, data: bytes | None = None) -> None:
        self.path, self.sha256, self.threads = str(path), sha256, threads
        if data is None:
            data, _ = read_checked(path, sha256)
        self._data = data
        self._session = open_session(data, path, threads)
        self._input = self._session.get_inputs()[0].name
        outputs = [o.name for o in self._session.get_outputs()]
        self._logits = outputs[0]
        self.trunk_names = [n for n in outputs[1:] if n.startswith("trunk.")]

    def with_trunk(self, batch: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Logits and the trunk outputs (:attr:`trunk_names`) of a batch, from one pass."""
        out = run_session(self._session, [self._logits, *self.trunk_names],
                          {self._input: np.ascontiguousarray(batch, np.float32)}, "segmentation")
        return out[0], out[1:]

    def sibling(self, threads: int | None = None) -> OnnxEngine:
        """Another session of the same network, from the bytes this one was built from (not read again)."""
        return OnnxEngine(self.path, self.sha256, threads, data=self._data)

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "sha256": self.sha256, "threads": self.threads}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"], state["sha256"], state["threads"])  # type: ignore[misc]

    def logits(self, batch: np.ndarray) -> np.ndarray:
        """Logits of a (B, 3, H, W) float32 batch."""
        return run_session(self._session, [self._logits], {self._input: np.ascontiguousarray(batch, np.float32)},
                           "segmentation")[0]


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

    try:  # bounded (a UserFileError is a ValueError: named below)
        record = json.loads(userfiles.read_text(rec_path, what="ONNX engine record",
                                                max_bytes=userfiles.MAX_RECORD_BYTES))
        if not isinstance(record, dict) or record.get("format") != RECORD_FORMAT:
            raise ValueError(f"not a {RECORD_FORMAT} record")
        bound, onnx_sha = record["weights_sha256"], record["onnx_sha256"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise WeightsError(f"{rec_path}: unusable ONNX engine record ({exc})") from None
    if weights_sha256 is None or bound != weights_sha256:
        raise WeightsError(f"{rec_path}: records weights {bound}, the network is {weights_sha256} "
                           f"(export it again: uav-el export-onnx --beside)")
    return OnnxEngine(onnx_path, onnx_sha, threads)
