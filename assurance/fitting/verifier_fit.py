"""Fitting the candidate verifier end to end: crops, training, selection, ONNX export, the hash-checked record.

``fit_verifier`` collects the core model's candidates of the training split (with ``jitter`` mined discs each) and
of the held-out split (candidates only), trains ``VerifierNet`` (``assurance.fitting.verifier_train``), exports the
selected step to ONNX and checks ONNX Runtime against torch on the held-out crops, then writes the record
(``el.monitors.verifier``): crop geometry, the threshold (the largest whose recall of held-out unsafe candidates is
>= ``recall``, as the learned monitor's), the held-out figures, the training data's hash, the command and the
network whose candidates it learned from. With a learned model (``learned``), the fusion weight ``w`` of
``sigmoid(w logit(p_v) + (1 - w) logit(p_l))`` is chosen on the held-out candidates by AUROC, and its threshold the
same way. Nothing is chosen on a test split: the caller gives training and held-out folders only.
"""

from __future__ import annotations

import datetime as _dt
import json
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from assurance.dataio.layouts import iter_samples, located
from assurance.dataio.uavid import Sample, read_image
from assurance.files import atomic_write_bytes
from assurance.fitting.learned_monitor import check_recall, recall_threshold, split_sha256
from assurance.fitting.network_identity import network_record
from assurance.fitting.verifier_data import LOOKALIKE_RANK, CropSet, CropSettings, collect_crops
from assurance.fitting.verifier_net import VerifierNet
from assurance.fitting.verifier_train import (
    OPSET,
    TrainConfig,
    TrainResult,
    auroc,
    onnx_bytes,
    predict,
    to_size,
    train_verifier,
)
from el.base.hashing import sha256_bytes
from el.base.records import signed_document
from el.landing.core import run_core
from el.monitors.base import CandidateContext
from el.monitors.verifier import VERIFIER_FORMAT, VerifierSession, fused_score
from el.segmentation.contract import labels_of
from el.segmentation.lite import pretrained_provenance

FUSION_WEIGHTS: tuple[float, ...] = (0.25, 0.4, 0.5, 0.6, 0.75, 0.9)
MAX_DIFF = 1e-3


@dataclass(frozen=True, kw_only=True)
class VerifierFitOptions:
    """What :func:`fit_verifier` takes besides its data and training configuration: the core model's configuration
    (``core``: the candidates), ``jitter`` discs mined around each training candidate, ``lookalikes`` look-alike
    discs drawn per training scene (``assurance.fitting.verifier_data.lookalike_discs``), the ``recall`` of held-out
    unsafe candidates the threshold keeps, the first ``images`` scenes of each split (None: all), the learned model to
    fuse with (``learned``; None: no fusion), the network's record (``weights``; None: the one the segmenter
    reports), the ``command`` recorded, whether the encoder starts from ImageNet's weights (``pretrained``), and
    progress bars."""

    core: Any = None
    jitter: int = 3
    lookalikes: int = 0
    recall: float = 0.95
    images: int | None = None
    learned: Any = None
    weights: dict[str, Any] | None = None
    command: str | None = None
    pretrained: bool = True
    progress: bool = False

    def __post_init__(self) -> None:
        if self.jitter < 0:
            raise ValueError(f"jitter (mined discs per candidate) must be >= 0, got {self.jitter}")
        if self.lookalikes < 0:
            raise ValueError(f"lookalikes (look-alike discs per scene) must be >= 0, got {self.lookalikes}")
        check_recall(self.recall)
        if self.images is not None and self.images < 1:
            raise ValueError(f"images (scenes of each split) must be >= 1, got {self.images}")


@dataclass(frozen=True)
class OnnxExport:
    """The exported network as the record names it: its file (beside the record), its SHA-256, and the largest
    difference of P(unsafe) between ONNX Runtime and torch (:func:`check_export`)."""

    file: str
    sha256: str
    max_diff: float


@dataclass(frozen=True, kw_only=True)
class HeldOutChoice:
    """What the held-out split chose with: the verifier's P(unsafe) of its candidates (``p``), the ``recall`` of
    unsafe ones the threshold keeps, and the fusion with the learned monitor (:func:`choose_fusion`; None: none)."""

    p: np.ndarray
    recall: float
    fusion: dict[str, Any] | None = None


@dataclass(frozen=True, kw_only=True)
class VerifierSources:
    """What a verifier record rests on: the ``splits`` (folders; their hashes under ``*_sha256`` and scene counts
    under ``*_images``), the
    segmentation network's record (``weights``), the ``command``, the label set's name (``labels``) and the
    encoder's ImageNet provenance (``imagenet``; empty: a random start)."""

    splits: dict[str, Any]
    weights: dict[str, Any]
    command: str | None
    labels: str
    imagenet: dict[str, Any]


def export_onnx(model: VerifierNet) -> bytes:
    """The ONNX bytes of the verifier's logit: input ``crops`` (B, 3, S, S) float in [0, 1], output ``logit`` (B,)."""
    import torch

    class LogitOnly(torch.nn.Module):
        def __init__(self, net: VerifierNet) -> None:
            super().__init__()
            self.net = net

        def forward(self, x: Any) -> Any:
            return self.net(x)[0]

    model.eval()
    return onnx_bytes(LogitOnly(model), model.size, ["logit"])


def onnx_probabilities(data: bytes, crops: np.ndarray, *, threads: int = 1, batch: int = 64) -> np.ndarray:
    """P(unsafe) of crops (n, S, S, 3) uint8 from the exported network, through the flying code's session: (n,)."""
    return VerifierSession(data, crops.shape[1], source="verifier export", threads=threads).probabilities(
        crops, batch=batch)


def check_export(data: bytes, model: VerifierNet, crops: np.ndarray) -> float:
    """The largest difference of P(unsafe) between ONNX Runtime and torch on ``crops``; ValueError above
    :data:`MAX_DIFF`."""
    diff = float(np.abs(onnx_probabilities(data, crops) - predict(model, crops)).max()) if len(crops) else 0.0
    if diff > MAX_DIFF:
        raise ValueError(f"verifier export: ONNX Runtime differs from torch by {diff:.2e} (> {MAX_DIFF:g})")
    return diff


def held_out_figures(y: np.ndarray, p: np.ndarray, threshold: float) -> dict[str, Any]:
    rejected = p > threshold
    return {"candidates": int(y.size), "unsafe": int(y.sum()), "auroc": auroc(y, p),
            "recall": float(rejected[y].mean()) if y.any() else None,
            "safe_rejected": float(rejected[~y].mean()) if (~y).any() else None}


def choose_fusion(y: np.ndarray, p_verifier: np.ndarray, p_learned: np.ndarray, *, learned_sha256: str,
                  recall: float, weights: Sequence[float] = FUSION_WEIGHTS) -> dict[str, Any]:
    """The fusion weight with the best held-out AUROC, its recall threshold and figures."""
    trials = [(auroc(y, fused_score(p_verifier, p_learned, w)), w) for w in weights]
    best_auc, w = max(trials)
    p = fused_score(p_verifier, p_learned, w)
    threshold = recall_threshold(p, y, recall)
    return {"weight": w, "threshold": threshold, "learned_sha256": learned_sha256,
            "trials": [{"weight": w_, "auroc": a} for a, w_ in trials],
            "held_out": held_out_figures(y, p, threshold), "learned_alone_auroc": auroc(y, p_learned)}


def verifier_body(result: TrainResult, cfg: TrainConfig, train: CropSet, held: CropSet, *, export: OnnxExport,
                  choice: HeldOutChoice, sources: VerifierSources) -> dict[str, Any]:
    """The record's body (``el.monitors.verifier.VerifierModel``)."""
    p_held, recall, splits = choice.p, choice.recall, sources.splits
    y = held.unsafe[held.is_candidate]
    threshold = recall_threshold(p_held, y, recall)
    return {
        "onnx": {"file": export.file, "sha256": export.sha256, "opset": OPSET, "max_diff_vs_torch": export.max_diff},
        "crop": {"size": cfg.size, "margin": cfg.margin}, "threshold": threshold,
        "criterion": {"name": "tnr-at-recall", "recall": recall, "on": "held-out core-model candidates"},
        "network": {"name": "VerifierNet", "encoder": f"EfficientNet-Lite0 stem + blocks 0-{result.model.depth - 1} "
                                                      f"({'ImageNet' if sources.imagenet else 'random'} start)",
                    "fuse_layers": result.model.fuse_layers,
                    "parameters": int(sum(p.numel() for p in result.model.parameters())),
                    "imagenet_weights": sources.imagenet},
        "training": {"crops": int(train.unsafe.size), "unsafe": int(train.unsafe.sum()),
                     "candidates": int(train.is_candidate.sum()),
                     "mined": int((~train.is_candidate).sum()),
                     "lookalikes": int((train.rank == LOOKALIKE_RANK).sum()), "config": dict(cfg.__dict__),
                     "steps_run": result.steps_run, "selected_step": result.best_step,
                     "seconds": round(result.seconds, 1), "curve": result.curve, "sha256": splits.get("train_sha256"),
                     "images": splits.get("train_images")},
        "held_out": {**held_out_figures(y, p_held, threshold), "sha256": splits.get("held_out_sha256"),
                     "images": splits.get("held_out_images")},
        "fusion": choice.fusion,
        "splits": {k: v for k, v in splits.items() if not k.endswith(("_sha256", "_images"))},
        "weights": sources.weights, "labels": sources.labels, "command": sources.command,
        "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }


def learned_scores(samples: Sequence[Sample], segmenter: Any, learned: Any, *, core: Any) -> np.ndarray:
    """The learned monitor's scores of the core model's candidates of ``samples``, in the crops' order."""
    out: list[float] = []
    for s in samples:
        rgb = read_image(s.image_path)
        probs = segmenter.predict_frame(rgb)
        size = (rgb.shape[1], rgb.shape[0])
        cands = run_core(probs, size, core, labels=labels_of(segmenter)).candidates
        ctx = [CandidateContext(c, probs, size) for c in cands]
        out += [v.score for v in learned.check_many(rgb, cands, segmenter, seeds=list(range(len(cands))),
                                                    contexts=ctx)]
    return np.asarray(out, np.float64)


def write_verifier(out: Path, body: dict[str, Any], onnx: bytes) -> dict[str, Any]:
    """Write the ONNX file (``body["onnx"]["file"]``, beside ``out``) and the record; the document."""
    atomic_write_bytes(out.parent / body["onnx"]["file"], onnx)
    doc = signed_document(VERIFIER_FORMAT, body)
    atomic_write_bytes(out, (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode())
    return doc


def fit_verifier(data: str | Path, val: str | Path, segmenter: Any, out: Path, *, cfg: TrainConfig,
                 options: VerifierFitOptions | None = None, log: Any = print) -> dict[str, Any]:
    """Collect, train, select on ``val``, export, write ``out`` (and its ONNX beside it): the document.
    ``options``: :class:`VerifierFitOptions` (None: its defaults)."""
    o = options or VerifierFitOptions()
    core, recall, images, learned = o.core, o.recall, o.images, o.learned
    weights = o.weights if o.weights is not None else network_record(segmenter, loaded=False)
    cut = CropSettings(core=core, size=128 if cfg.size <= 128 else cfg.size, margin=cfg.margin)
    train_samples = list(iter_samples(data, require_labels=True))[:images]  # each split listed once
    held_samples = list(iter_samples(val, require_labels=True))[:images]
    with tempfile.TemporaryDirectory(prefix="uav-el-verifier-") as tmp:  # the training crops and features lie on disk
        mined = replace(cut, jitter=o.jitter, lookalikes=o.lookalikes)
        train = collect_crops(data, segmenter, settings=mined, samples=train_samples,
                              desc="training scenes", progress=o.progress, spill=Path(tmp) / "train-crops.u8")
        held = collect_crops(val, segmenter, settings=cut, samples=held_samples, desc="held-out scenes",
                             progress=o.progress)
        result = train_verifier(train, held, cfg, pretrained=o.pretrained, log=log, spill=Path(tmp))
        train.crops = train.crops[:0].copy()  # the mapping closes before its folder goes
    sel = held.is_candidate
    crops = to_size(held.crops[sel], cfg.size)
    onnx = export_onnx(result.model)
    diff = check_export(onnx, result.model, crops[:64])
    p_held = onnx_probabilities(onnx, crops, threads=cfg.threads)  # the threshold is the flying network's
    fusion = None
    if learned is not None:
        p_learned = learned_scores(held_samples, segmenter, learned, core=core)
        fusion = choose_fusion(held.unsafe[sel], p_held, p_learned, learned_sha256=learned.model_sha256,
                               recall=recall)
    splits = {"train": str(data), "held_out": str(val), "spec": {"train": located(data), "held_out": located(val)},
              "train_sha256": split_sha256(train_samples, data), "held_out_sha256": split_sha256(held_samples, val),
              "train_images": len(train_samples), "held_out_images": len(held_samples)}
    body = verifier_body(result, cfg, train, held,
                         export=OnnxExport(out.with_suffix(".onnx").name, sha256_bytes(onnx), diff),
                         choice=HeldOutChoice(p=p_held, recall=recall, fusion=fusion),
                         sources=VerifierSources(splits=splits, weights=weights, command=o.command,
                                                 labels=labels_of(segmenter).name,
                                                 imagenet=pretrained_provenance() if o.pretrained else {}))
    return write_verifier(out, body, onnx)
