"""Check a model card against its weights and data, or re-issue its figures on another copy of the data.

Used by ``uav-el model-card --verify``: the weights' SHA-256 is checked (loading fails otherwise),
the validation data are hashed and compared with the recorded hash, and the per-class IoU, mIoU and
confusion matrices at both scales are recomputed with the recorded protocol. Optionally the per-pixel
baseline is refitted on the training data and its mIoU compared.

``uav-el model-card --reissue`` (:func:`reissue_card`) recomputes the same figures on this machine's
copy of the scenes and writes them into the card: the generator reproduces every label bit for bit
from its seeds, but rendered pixels can differ by rounding between processors, so a model trained
on another machine (a GPU box) gets its card's figures from the copy its users can regenerate.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from assurance.fitting.network import data as D
from assurance.fitting.network.baseline import evaluate_baseline
from assurance.fitting.network.evaluation import compare_figures, evaluate
from assurance.fitting.network.weights_io import write_card
from el.segmentation.inference import Segmenter
from el.segmentation.protocol import EvalProtocol
from el.segmentation.weights import DEFAULT_WEIGHTS, load_weights


@dataclass
class Verification:
    """Outcome of :func:`verify_card`: ``checks`` passed (readable lines) and ``problems`` found."""

    weights: Path
    checks: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    recomputed: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.problems


def verify_card(weights_path: str | Path | None = None, *, val_dir: str | Path | None = None,
                train_dir: str | Path | None = None, threads: int | None = None, iou_tol: float = 0.002,
                progress: Callable[..., Iterable] | None = None) -> Verification:
    """Recompute a model card's figures from its weights and validation data and compare them.

    ``val_dir`` defaults to the folder recorded in the card; ``train_dir`` (optional) also refits and
    checks the per-pixel baseline. Raises WeightsError if the weights cannot be loaded (missing file,
    SHA-256 mismatch) and DataError for unreadable data; disagreements are listed in ``problems``.
    """
    path = Path(weights_path) if weights_path is not None else DEFAULT_WEIGHTS
    model, card = load_weights(path)
    result = Verification(path)
    result.checks.append(f"weights SHA-256 matches the card ({card['weights_sha256'][:16]}...)")
    evaluation = card.get("evaluation")
    if not evaluation:
        result.problems.append("the card records no evaluation figures (trained without validation data)")
        return result
    recorded_data = evaluation.get("data") or {}
    val_root = Path(val_dir) if val_dir is not None else Path(recorded_data.get("path", ""))
    if val_dir is None and not recorded_data.get("path"):
        result.problems.append("no validation folder given and none recorded in the card")
        return result
    workers = threads or 2
    manifest = D.dataset_manifest(val_root, threads=workers)
    if manifest.sha256 == recorded_data.get("sha256"):
        result.checks.append(f"validation data hash matches ({manifest.sha256[:16]}..., "
                             f"{len(manifest.samples)} images)")
    else:
        result.problems.append(f"validation data hash differs: recorded {recorded_data.get('sha256')}, "
                               f"{val_root} has {manifest.sha256}")
    protocol = EvalProtocol.from_dict(evaluation["protocol"])
    val_set, figures = _evaluate_on(model, card, manifest, protocol, threads, workers, progress)
    result.recomputed["evaluation"] = figures
    diffs = compare_figures(evaluation, figures, iou_tol=iou_tol)
    if diffs:
        result.problems.extend(diffs)
    else:
        wr, hd = figures["working_resolution"]["miou"], figures["hd_patches"]["miou"]
        result.checks.append(f"per-class IoU, mIoU and confusion matrices reproduced (mIoU working {wr:.4f}, "
                             f"HD patches {hd if hd is None else round(hd, 4)})")

    baseline = card.get("baseline")
    if train_dir is not None:
        if not baseline:
            result.problems.append("--train given but the card records no baseline")
            return result
        train_manifest = D.dataset_manifest(train_dir, threads=workers)
        trained_on = ((card.get("training") or {}).get("data") or {}).get("train")
        recorded_train = baseline.get("train_data") or trained_on or {}
        if train_manifest.sha256 != recorded_train.get("sha256"):
            result.problems.append(f"training data hash differs: recorded {recorded_train.get('sha256')}, "
                                   f"{train_dir} has {train_manifest.sha256}")
        recomputed = _refit_baseline(train_manifest, val_set, baseline, protocol, workers, progress)
        result.recomputed["baseline"] = recomputed
        if abs(recomputed["miou"] - baseline["miou"]) > iou_tol:
            result.problems.append(f"baseline mIoU: recorded {baseline['miou']}, recomputed {recomputed['miou']}")
        else:
            result.checks.append(f"baseline mIoU reproduced ({recomputed['miou']:.4f})")
    return result


def _evaluate_on(model: Any, card: dict[str, Any], manifest: D.Manifest, protocol: EvalProtocol,
                 threads: int | None, workers: int, progress: Callable[..., Iterable] | None
                 ) -> tuple[list[D.Prepared], dict[str, Any]]:
    """The prepared validation samples and the network's figures on them, by the recorded protocol."""
    val_set = D.load_dataset(manifest, D.protocol_prep(protocol), cache_dir=None, threads=workers, progress=progress)
    segmenter = Segmenter.for_protocol(model, protocol, threads=threads, card=card, labels=D.TRAINING_LABELS)
    return val_set, evaluate(segmenter, val_set, progress=progress, total=len(val_set))


def _refit_baseline(train_manifest: D.Manifest, val_set: list[D.Prepared], params: dict[str, Any],
                    protocol: EvalProtocol, workers: int, progress: Callable[..., Iterable] | None) -> dict[str, Any]:
    """The per-pixel baseline fitted on the training frames with the card's recorded parameters."""
    train_set = D.load_dataset(train_manifest, D.PrepParams(working_width=protocol.working_width, regions=0),
                               cache_dir=None, threads=workers, progress=progress)
    return evaluate_baseline([s.image for s in train_set], [s.labels for s in train_set],
                             [s.image for s in val_set], [s.labels for s in val_set],
                             max_pixels=int(params["max_pixels"]), seed=int(params["seed"]),
                             max_iter=int(params.get("max_iter", 300)))


@dataclass(frozen=True, kw_only=True)
class ProtocolChanges:
    """What a re-issued card changes in its recorded evaluation protocol (each None: as recorded). ``frame_flip``
    changes how frames are segmented, in the figures and in deployment, since :meth:`Segmenter.load` follows the
    card's protocol, and so does ``frame_scales`` (the sizes the working frame is fed at) and ``frame_pooling`` (how
    their softmax comes back); ``hd_patches`` sets the HD validation patches per frame (more patches: a steadier HD
    figure). Checked as the protocol is (``el.segmentation.protocol.EvalProtocol``) when the card is re-issued."""

    frame_flip: bool | None = None
    hd_patches: int | None = None
    frame_scales: Sequence[float] | None = None
    frame_pooling: str | None = None


def reissue_card(weights_path: str | Path | None = None, *, val_dir: str | Path, train_dir: str | Path | None = None,
                 threads: int | None = None, progress: Callable[..., Iterable] | None = None,
                 changes: ProtocolChanges | None = None) -> dict[str, Any]:
    """Recompute the card's evaluation (and, with ``train_dir``, the baseline) on these folders; write it.

    The training record (what the network was trained and selected on) is kept; the evaluation names
    the data it was computed on and keeps the figures it replaces under ``reissued``. ``changes``: what changes in
    the recorded protocol (:class:`ProtocolChanges`; None: nothing). Returns the card.
    """
    changes = changes or ProtocolChanges()
    frame_flip, hd_patches = changes.frame_flip, changes.hd_patches
    frame_scales, frame_pooling = changes.frame_scales, changes.frame_pooling
    path = Path(weights_path) if weights_path is not None else DEFAULT_WEIGHTS
    model, card = load_weights(path)
    old = card.get("evaluation")
    if not old:
        raise ValueError(f"{path}: the card records no evaluation protocol (trained without validation data)")
    workers = threads or 2
    protocol = EvalProtocol.from_dict(old["protocol"])
    if frame_flip is not None:
        protocol = replace(protocol, frame_flip=bool(frame_flip))
    if hd_patches is not None:
        protocol = replace(protocol, hd_patches=int(hd_patches))
    if frame_scales is not None:
        protocol = replace(protocol, frame_scales=frame_scales)
    if frame_pooling is not None:
        protocol = replace(protocol, frame_pooling=frame_pooling)
    manifest = D.dataset_manifest(val_dir, threads=workers)
    val_set, figures = _evaluate_on(model, card, manifest, protocol, threads, workers, progress)
    previous = {"data": old.get("data"), "protocol": old["protocol"],
                "miou_working": old["working_resolution"]["miou"], "miou_hd": old["hd_patches"]["miou"]}
    card["evaluation"] = {**old, **figures, "data": manifest.describe(), "protocol": protocol.to_dict(),
                          "reissued": previous}
    baseline = card.get("baseline")
    if train_dir is not None:
        params = baseline or {"max_pixels": 200_000, "seed": (card.get("training") or {}).get("seed", 0)}
        train_manifest = D.dataset_manifest(train_dir, threads=workers)
        baseline = _refit_baseline(train_manifest, val_set, params, protocol, workers, progress)
        baseline["train_data"] = train_manifest.describe()
    if baseline:
        cnn, base = figures["working_resolution"]["miou"], baseline["miou"]
        baseline["miou_gap_to_cnn"] = None if cnn is None or base is None else cnn - base
        card["baseline"] = baseline
    card.pop("candidates", None)  # measured on the other copy; the caller re-runs the audit
    write_card(path, card)
    return card
