"""The deployed frame gate: one fitted candidate of ``el.monitors.gates``, read from its hash-checked JSON file
(``uav-el fit-gate``), scoring the statistics the frame's own segmentation pass returned with its probabilities
(``predict_frame(rgb, stats=True)``, ``el/segmentation/frame_tap.py``: no second pass, nothing kept on the model).
Any network offering them (``el.segmentation.contract.FRAME_STATS``) can carry a gate: the shipped ``Segmenter``
(torch or ONNX Runtime), an ONNX file (``OnnxModel``) and either behind a class map (``MappedModel`` passes its
network's statistics through). The file's ``features.tap`` says which statistics it reads: ``pooled`` (the
trunk's), ``output`` (the logits', every network's) or ``energy``.

A frame whose score is above the threshold ends in the default action with reason
``out_of_domain: frame gate <kind> score S > threshold T`` (a decision: there is no evidence of safety there);
a fault of the gate (no statistics, wrong feature count, a non-finite score) is a fault of the decision (default
action, the reason recorded). The file binds the gate to the network it was fitted on (``weights.sha256``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from el.base.errors import FrameGateError
from el.base.records import HashedRecord
from el.monitors.gates import GATES
from el.segmentation.contract import FRAME_STATS, has_capability

FRAME_GATE_FORMAT = "uav-el-frame-gate/1"
OUT_OF_DOMAIN = "out_of_domain"
"""The prefix of the reason of a frame the gate refuses."""


def _arrays(value: Any) -> Any:
    """The fitted statistics with every list of numbers as a numpy array (converted once, at load)."""
    if isinstance(value, dict):
        return {k: _arrays(v) for k, v in value.items()}
    if isinstance(value, list) and value and not isinstance(value[0], str):
        arr = np.asarray(value, np.float64)
        if not np.isfinite(arr).all():
            raise ValueError("non-finite fitted statistics")
        return arr
    return value


@dataclass(frozen=True)
class FrameGate(HashedRecord):
    """A checked frame gate (:func:`load_frame_gate`): its kind, fitted statistics and threshold."""

    FORMAT: ClassVar[str] = FRAME_GATE_FORMAT
    WHAT: ClassVar[str] = "frame gate"
    ERROR: ClassVar[type[ValueError]] = FrameGateError

    params: dict[str, Any]

    @property
    def kind(self) -> str:
        return str(self.body["kind"])

    @property
    def threshold(self) -> float:
        return float(self.body["threshold"])

    @property
    def dims(self) -> int:
        return int(self.body["features"]["dims"])

    @property
    def features(self) -> str:
        """Which statistics of the frame's tap the gate reads (``pooled``: the trunk's; ``output``; ``energy``)."""
        return str(self.body["features"].get("tap") or GATES[self.kind].FEATURES[0])

    @property
    def needs_trunk(self) -> bool:
        return self.features == "pooled"

    def score(self, stats: Any) -> float:
        """The frame's score from its pass's :class:`~el.segmentation.frame_tap.FrameTap`; ValueError when the pass
        returned none, the features do not match the fitted ones, or the score is not finite."""
        if stats is None:
            raise ValueError("the segmentation pass returned no frame statistics (predict_frame(rgb, stats=True))")
        gate = GATES[self.kind]
        x = np.asarray(gate.embed(stats, self.features), np.float64)
        if x.shape != (self.dims,):
            raise ValueError(f"the frame has {x.size} features, the gate {self.path} was fitted on {self.dims} "
                             "(another network or engine?)")
        value = float(gate.score(self.params, x[None])[0])
        if not math.isfinite(value):
            raise ValueError("non-finite frame-gate score")
        return value

    def reason(self, score: float) -> str | None:
        """``out_of_domain: ...`` when ``score`` is above the threshold (or not a number), else None."""
        if score <= self.threshold:
            return None
        return f"{OUT_OF_DOMAIN}: frame gate {self.kind} score {score:.4g} > threshold {self.threshold:.4g}"

    def record(self, score: float | None) -> dict[str, Any]:
        """What a decision records of the gate: kind, score (None when the frame was not scored), threshold,
        and the file's body SHA-256."""
        return {"kind": self.kind, "score": score, "threshold": self.threshold, "sha256": self.sha256}


def frame_gate_document(body: dict[str, Any]) -> dict[str, Any]:
    """The JSON document of a gate with this body (format and hash added)."""
    return FrameGate.document(body)


def load_frame_gate(path: str | Path) -> FrameGate:
    """Read and check a frame-gate file: format, body hash, kind, feature count, threshold, finite statistics.

    Raises
    ------
    FrameGateError
        One line naming the file and the problem.
    """
    p = Path(path)
    body, digest = FrameGate.read_body(p)
    try:
        if body.get("kind") not in GATES:
            raise ValueError(f"kind must be one of {', '.join(sorted(GATES))}, got {body.get('kind')!r}")
        dims = body["features"]["dims"]
        tap = body["features"].get("tap") or GATES[body["kind"]].FEATURES[0]
        if tap not in GATES[body["kind"]].FEATURES:
            raise ValueError(f"features.tap {tap!r}: a {body['kind']} gate reads "
                             f"{' or '.join(GATES[body['kind']].FEATURES)}")
        if isinstance(dims, bool) or not isinstance(dims, int) or dims < 1:
            raise ValueError(f"features.dims must be a positive integer, got {dims!r}")
        if not math.isfinite(float(body["threshold"])):
            raise ValueError("threshold must be a finite number")
        params = _arrays(body["params"])
        GATES[body["kind"]].score(params, np.zeros((1, dims)))  # the statistics fit the feature count
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise FrameGateError(f"{p}: inconsistent frame gate ({exc})") from None
    return FrameGate(str(p), digest, body, params)


@dataclass(frozen=True)
class GateFile:
    """Which frame gate a configuration deploys: its file, and the body SHA-256 it must have (None: whatever the
    file holds when it is read). One type for the flight's ``PipelineConfig.gate`` and the campaign's
    ``CampaignConfig.gate`` (which pins the hash its run recorded)."""

    path: str
    sha256: str | None = None

    @classmethod
    def of(cls, value: GateFile | FrameGate | str | Path | Mapping[str, Any] | None) -> GateFile | None:
        """The gate file a configuration is given: a path (unpinned), a loaded gate or a run's ``{"path",
        "sha256"}`` record (pinned); None or empty: no gate."""
        if value is None or isinstance(value, GateFile):
            return value
        if isinstance(value, FrameGate):
            return cls(value.path, value.sha256)
        if isinstance(value, Mapping):
            return cls(str(value["path"]), value.get("sha256")) if value else None
        return cls(str(value)) if str(value) else None

    def to_dict(self) -> dict[str, str | None]:
        return {"path": self.path, "sha256": self.sha256}

    def load(self) -> FrameGate:
        """The gate, read and checked (``load_frame_gate``); FrameGateError when a pinned file's body changed."""
        gate = load_frame_gate(self.path)
        if self.sha256 is not None and gate.sha256 != self.sha256:
            raise FrameGateError(f"{self.path}: frame gate changed since the run recorded it (body SHA-256 "
                                 f"{gate.sha256[:12]}..., recorded {self.sha256[:12]}...)")
        return gate


def returns_frame_stats(model: Any) -> bool:
    """Whether a segmentation model returns its frame pass's statistics for a frame gate (``FRAME_STATS``: the
    shipped ``Segmenter``, an ``OnnxModel``, a ``MappedModel`` over either)."""
    return has_capability(model, FRAME_STATS)


def check_frame_stats(model: Any, where: str) -> None:
    """``FrameGateError`` naming ``where`` for a model that returns no frame statistics (a gate cannot read it)."""
    if not returns_frame_stats(model):
        inner = getattr(model, "network", model)
        raise FrameGateError(f"{where}: the segmentation model {type(inner).__name__} returns no frame statistics "
                             "(predict_frame(rgb, stats=True), el.segmentation.contract.FRAME_STATS): a frame gate "
                             "cannot read it")


def bind_frame_gate(gate: FrameGate | str | Path, segmenter: Any) -> FrameGate:
    """The gate (a loaded one, or the file at a path) for ``segmenter``: refused (its error, one line) when fitted on
    another network or when the segmenter returns no frame statistics. Changes nothing on the segmenter."""
    gate = gate if isinstance(gate, FrameGate) else load_frame_gate(gate)
    if segmenter is None:
        raise FrameGateError(f"{gate.path}: no segmentation network to bind the frame gate to")
    gate.check_network(segmenter)
    check_frame_stats(segmenter, gate.path)
    return gate


def judge_frame(gate: FrameGate, stats: Any, info: dict[str, Any]) -> str | None:
    """Score a frame from its segmentation pass's statistics; record it in ``info["frame_gate"]`` and return the
    ``out_of_domain`` reason when it is above the threshold. ValueError (a fault) when it cannot be scored."""
    score = gate.score(stats)
    info["frame_gate"] = gate.record(score)
    return gate.reason(score)


__all__ = ["FRAME_GATE_FORMAT", "OUT_OF_DOMAIN", "FrameGate", "GateFile", "bind_frame_gate", "check_frame_stats",
           "frame_gate_document", "judge_frame", "load_frame_gate", "returns_frame_stats"]
