"""``verifier``: a diverse candidate verifier, a small CNN of its own that scores a candidate's pixels "unsafe".

Every other monitor reads the segmentation network's softmax, so it shares the network's errors (the look-alike
discs the network paints safe). The verifier does not: it reads the full-resolution pixels of the candidate's disc
and a margin, resampled to a fixed size in metres (``el.monitors.verifier_crop``), and a CNN trained on the
core model's train-split candidates (``uav-el fit-verifier``) gives P(the disc holds a forbidden ground-truth
pixel), the definition the campaign judges by. Rejected iff score > threshold.

``verifier:fuse=learned`` composes it with the learned monitor (``el.monitors.learned``): the score is
``sigmoid(w logit(p_verifier) + (1 - w) logit(p_learned))``, ``w`` chosen on validation and recorded in the
verifier's file (``fusion``), which also names the learned model it was chosen with (its SHA-256 is checked).

The file is a hash-checked record (``el.base.records.HashedRecord``, format :data:`VERIFIER_FORMAT`) beside its ONNX
network: the record holds the ONNX file's name and SHA-256 (checked before ONNX Runtime sees a byte), the crop
size and margin, the threshold, the training data's hash, the command, the validation figures and the segmentation
network whose candidates it was trained on. Inference is ONNX Runtime (the light install's engine; no torch), one
batch per frame's candidates (:meth:`VerifierMonitor.check_many`), under the decision's deadline.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from el.base.deadline import checkpoint
from el.base.decision import Candidate, Disc, MonitorVerdict
from el.base.errors import LearnedModelError
from el.base.records import HashedRecord
from el.classes.labels import LabelSet
from el.monitors.base import CandidateContext, Clock, Monitor, batch_arguments
from el.monitors.learned import LearnedMonitor
from el.monitors.spec import GenericSpec
from el.monitors.verifier_crop import MAX_MARGIN, candidate_crop
from el.segmentation.onnx_engine import open_session, read_checked, run_session

VERIFIER_FORMAT = "uav-el-verifier/1"
DEFAULT_VERIFIER = Path(__file__).resolve().parent / "data" / "verifier.json"
FUSE_CHOICES = ("none", "learned")
EPS = 1e-6


@dataclass(frozen=True)
class VerifierModel(HashedRecord):
    """A checked verifier file (:func:`load_verifier`) and the ONNX bytes it names."""

    FORMAT: ClassVar[str] = VERIFIER_FORMAT
    WHAT: ClassVar[str] = "candidate verifier"
    ERROR: ClassVar[type[ValueError]] = LearnedModelError

    onnx: bytes
    onnx_path: str

    @property
    def size(self) -> int:
        return int(self.body["crop"]["size"])

    @property
    def margin(self) -> float:
        return float(self.body["crop"]["margin"])

    @property
    def threshold(self) -> float:
        return float(self.body["threshold"])

    @property
    def fusion(self) -> dict[str, Any] | None:
        fusion = self.body.get("fusion")
        return fusion if isinstance(fusion, dict) else None


def load_verifier(path: str | Path | None = None) -> VerifierModel:
    """Read and check a verifier file (default: the shipped ``el/monitors/data/verifier.json``) and its ONNX
    network (a file in the same folder, named by the record, with the SHA-256 it records).

    Raises
    ------
    LearnedModelError
        One line naming the file and the problem (missing, altered, inconsistent, its network missing or altered).
    """
    p = Path(path) if path else DEFAULT_VERIFIER
    hint = " (train one with: uav-el fit-verifier --system uav-el.toml --out FILE)"
    body, digest = VerifierModel.read_body(p, hint=hint)
    try:
        name, sha = str(body["onnx"]["file"]), str(body["onnx"]["sha256"])
        size, margin = int(body["crop"]["size"]), float(body["crop"]["margin"])
        threshold = float(body["threshold"])
        if Path(name).name != name or name in ("", ".", ".."):
            raise ValueError(f"the ONNX file must lie beside the record (a plain name), got {name!r}")
        if not (8 <= size <= 512 and size % 16 == 0):
            raise ValueError(f"crop size must be a multiple of 16 in [16, 512], got {size}")
        if not (0.0 <= margin <= MAX_MARGIN and math.isfinite(threshold)):
            raise ValueError(f"crop margin must lie in [0, {MAX_MARGIN:g}] and the threshold be finite")
        fusion = body.get("fusion")
        if fusion is not None and not (0.0 <= float(fusion["weight"]) <= 1.0):
            raise ValueError("fusion weight must lie in [0, 1]")
    except (KeyError, TypeError, ValueError) as exc:
        raise LearnedModelError(f"{p}: inconsistent candidate verifier ({exc})") from None
    onnx_path = p.parent / name
    try:
        data, _ = read_checked(onnx_path, sha)
    except ValueError as exc:
        raise LearnedModelError(f"{p}: its network: {exc}") from None
    return VerifierModel(str(p), digest, body, data, str(onnx_path))


def logit(p: np.ndarray) -> np.ndarray:
    """log(p / (1 - p)), p clipped to [EPS, 1 - EPS]."""
    q = np.clip(np.asarray(p, np.float64), EPS, 1.0 - EPS)
    return np.log(q) - np.log1p(-q)


def fused_score(p_verifier: np.ndarray, p_learned: np.ndarray, weight: float) -> np.ndarray:
    """``sigmoid(w logit(p_verifier) + (1 - w) logit(p_learned))``: the composed score, a probability."""
    z = weight * logit(p_verifier) + (1.0 - weight) * logit(p_learned)
    return 1.0 / (1.0 + np.exp(-np.clip(z, -500.0, 500.0)))


class VerifierSession:
    """A verifier network under ONNX Runtime: crops (n, S, S, 3) uint8 -> P(unsafe) (n,). Built from the ONNX bytes
    and crop size alone, so the fitting scores its held-out crops with the code that flies. Picklable."""

    def __init__(self, onnx: bytes, size: int, *, source: str = "verifier", threads: int | None = 1) -> None:
        self.onnx, self.size, self.source, self.threads = onnx, size, source, threads
        self._session = open_session(onnx, source, threads)
        self._input = self._session.get_inputs()[0].name
        self._output = self._session.get_outputs()[0].name

    @classmethod
    def of(cls, model: VerifierModel, threads: int | None = 1) -> VerifierSession:
        """The session of a verifier file's network."""
        return cls(model.onnx, model.size, source=str(model.onnx_path), threads=threads)

    def __getstate__(self) -> dict[str, Any]:
        return {"onnx": self.onnx, "size": self.size, "source": self.source, "threads": self.threads}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["onnx"], state["size"], source=state["source"], threads=state["threads"])  # type: ignore[misc]

    def probabilities(self, crops: np.ndarray, *, batch: int | None = None) -> np.ndarray:
        """P(unsafe) of ``crops``; ``batch``: run at most that many crops at a time (a frame's crops run at once)."""
        if crops.ndim != 4 or crops.shape[1:] != (self.size, self.size, 3) or crops.dtype != np.uint8:
            raise ValueError(f"verifier crops must be (n, {self.size}, {self.size}, 3) uint8, "
                             f"got {crops.shape} {crops.dtype}")
        step = batch or max(len(crops), 1)
        z = np.concatenate([self._logits(crops[i:i + step]) for i in range(0, len(crops), step)] or [np.zeros(0)])
        if not np.isfinite(z).all():
            raise ValueError("verifier: non-finite logits")
        return 1.0 / (1.0 + np.exp(-np.clip(z, -500.0, 500.0)))

    def _logits(self, crops: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(crops.transpose(0, 3, 1, 2), np.float32) / np.float32(255.0)
        (z,) = run_session(self._session, [self._output], {self._input: x}, "verifier")
        return np.asarray(z, np.float64).reshape(len(crops))


def _patch_keywords(*, margin: float = 0.25, max_side: int | None = None,
                    clock: Clock = time.perf_counter) -> dict[str, Any]:
    """The patch keywords a registered monitor takes (``el.monitors.registry.MonitorEntry``), with their defaults;
    TypeError for another keyword."""
    return {"margin": margin, "max_side": max_side, "clock": clock}


class VerifierMonitor(Monitor):
    """``verifier[:model=FILE][,fuse=learned]``: P(unsafe) of the candidate's pixels from a CNN of its own.

    The default threshold is the file's (``fusion.threshold`` with ``fuse=learned``); a calibration card or
    ``threshold=X`` sets another. ``fuse=learned`` also reads the learned monitor (``learned=FILE``: its file,
    default the shipped one, which must be the one the fusion was chosen with) and needs the candidate's context.
    """

    PARAMS: ClassVar[dict[str, Any]] = {"model": str, "fuse": str, "learned": str}
    SCORE_RANGE: ClassVar[tuple[float, float]] = (0.0, 1.0)

    def __init__(self, *, labels: LabelSet, model: str | None = None, fuse: str = "none",
                 threshold: float | None = None, learned: str | None = None, threads: int | None = 1,
                 **common: Any) -> None:
        """``common``: the patch keywords every registered monitor takes (``margin``, ``max_side``, ``clock``; see
        :func:`_patch_keywords`): the clock times the verifier, and all three go to the learned monitor it fuses
        with. ``threads``: ONNX Runtime's threads for the verifier's network."""
        common = _patch_keywords(**common)
        if fuse not in FUSE_CHOICES:
            raise ValueError(f"verifier: fuse must be one of {', '.join(FUSE_CHOICES)}, got {fuse!r}")
        self.labels, self.model_path, self.fuse, self.clock = labels, model, fuse, common["clock"]
        self.record = load_verifier(model)
        self.learned_path = learned
        self.learned = None
        default = self.record.threshold
        if fuse == "learned":
            self.learned, default = self._learned(learned, labels, common)
        elif learned is not None:
            raise ValueError("verifier: learned=FILE is read only with fuse=learned")
        self.DEFAULT_THRESHOLD = default  # type: ignore[misc]  # per file, not per class
        super().__init__(threshold=threshold)
        self.session = VerifierSession.of(self.record, threads)

    def _learned(self, path: str | None, labels: LabelSet, common: dict[str, Any]) -> tuple[Any, float]:
        fusion = self.record.fusion
        if fusion is None:
            raise LearnedModelError(f"{self.record.path}: no fusion with the learned monitor recorded "
                                    "(fit it with uav-el fit-verifier)")
        learned = LearnedMonitor(labels=labels, model=path, **common)
        if learned.model_sha256 != fusion.get("learned_sha256"):
            raise LearnedModelError(f"{self.record.path}: fused with learned model "
                                    f"{str(fusion.get('learned_sha256'))[:12]}..., but {learned.model.path} is "
                                    f"{learned.model_sha256[:12]}...")
        return learned, float(fusion["threshold"])

    @property
    def spec(self) -> GenericSpec:  # type: ignore[override]
        items: list[tuple[str, Any]] = []
        if self.model_path is not None:
            items.append(("model", self.model_path))
        if self.fuse != "none":
            items.append(("fuse", self.fuse))
        if self.learned_path is not None:
            items.append(("learned", self.learned_path))
        if self.threshold != self.DEFAULT_THRESHOLD:
            items.append(("threshold", self.threshold))
        return GenericSpec("verifier", tuple(items))

    @property
    def model_sha256(self) -> str:  # type: ignore[override]
        return self.record.sha256

    def check_network(self, segmenter: Any) -> None:
        """Refuse a network whose candidates the verifier was not trained on (and, fused, the learned model's)."""
        self.record.check_network(segmenter)
        if self.learned is not None:
            self.learned.check_network(segmenter)

    def crops(self, hd_image: np.ndarray, candidates: Sequence[Candidate | Disc]) -> np.ndarray:
        """The candidates' crops (n, S, S, 3) uint8 (``el.monitors.verifier_crop.candidate_crop``)."""
        size, margin = self.record.size, self.record.margin
        out = np.empty((len(candidates), size, size, 3), np.uint8)
        for k, c in enumerate(candidates):
            out[k] = candidate_crop(hd_image, c, size=size, margin=margin)
        return out

    def scores(self, hd_image: np.ndarray, candidates: Sequence[Candidate | Disc], segmenter: Any, *,
               seeds: Sequence[int], contexts: Sequence[CandidateContext | None]) -> tuple[np.ndarray, np.ndarray]:
        """The candidates' scores and the verifier's own P(unsafe), one batch for the frame."""
        checkpoint("monitoring")
        p = self.session.probabilities(self.crops(hd_image, candidates))
        checkpoint("monitoring")
        if self.learned is None:
            return p, p
        if any(c is None for c in contexts):
            raise ValueError("verifier:fuse=learned needs the candidate's context (frame softmax)")
        learned = self.learned.check_many(hd_image, candidates, segmenter, seeds=seeds, contexts=contexts)
        fusion = self.record.fusion or {}
        return fused_score(p, np.array([v.score for v in learned]), float(fusion["weight"])), p

    def check(self, hd_image: np.ndarray, candidate: Candidate | Disc, segmenter: Any, *, seed: int = 0,
              context: CandidateContext | None = None) -> MonitorVerdict:
        return self.check_many(hd_image, [candidate], segmenter, seeds=[seed], contexts=[context])[0]

    def check_many(self, hd_image: np.ndarray, candidates: Sequence[Candidate | Disc], segmenter: Any, *,
                   seeds: Sequence[int], contexts: Sequence[CandidateContext | None] | None = None
                   ) -> list[MonitorVerdict]:
        """Every candidate of the frame in one ONNX batch; each verdict's ``seconds`` is its share of the frame's."""
        contexts = batch_arguments(candidates, seeds, contexts)
        t0 = self.clock()
        scores, own = self.scores(hd_image, candidates, segmenter, seeds=seeds, contexts=contexts)
        share = (self.clock() - t0) / max(1, len(candidates))
        out = []
        for s, p in zip(scores, own, strict=True):
            score = float(s)
            accepted = self.accepts(score)
            what = "P(unsafe)" if self.learned is None else f"fused P(unsafe) (verifier {float(p):.4f})"
            out.append(MonitorVerdict(self.name, accepted, f"{what} {score:.4f} {'<=' if accepted else '>'} "
                                                           f"threshold {self.threshold:.4g}", share, score,
                                      self.threshold))
        return out
