"""Check a model card against its weights and data: recompute the figures and compare.

Used by ``uav-el model-card --verify``: the weights' SHA-256 is checked (loading fails otherwise),
the validation data are hashed and compared with the recorded hash, and the per-class IoU, mIoU and
confusion matrices at both scales are recomputed with the recorded protocol. Optionally the per-pixel
baseline is refitted on the training data and its mIoU compared.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from el.segmentation import data as D
from el.segmentation.baseline import evaluate_baseline
from el.segmentation.evaluation import EvalProtocol, compare_figures, evaluate
from el.segmentation.inference import Segmenter
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
    segmenter = Segmenter(model, threads=threads, card=card, working_width=protocol.working_width)
    val_set = D.load_dataset(manifest, protocol.prep_params(), cache_dir=None, threads=workers, progress=progress)
    figures = evaluate(segmenter, val_set, progress=progress, total=len(val_set))
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
        recorded_train = ((card.get("training") or {}).get("data") or {}).get("train") or {}
        if train_manifest.sha256 != recorded_train.get("sha256"):
            result.problems.append(f"training data hash differs: recorded {recorded_train.get('sha256')}, "
                                   f"{train_dir} has {train_manifest.sha256}")
        train_set = D.load_dataset(train_manifest, D.PrepParams(working_width=protocol.working_width, regions=0),
                                   cache_dir=None, threads=workers, progress=progress)
        recomputed = evaluate_baseline([s.image for s in train_set], [s.labels for s in train_set],
                                       [s.image for s in val_set], [s.labels for s in val_set],
                                       max_pixels=int(baseline["max_pixels"]), seed=int(baseline["seed"]),
                                       max_iter=int(baseline.get("max_iter", 300)))
        result.recomputed["baseline"] = recomputed
        if abs(recomputed["miou"] - baseline["miou"]) > iou_tol:
            result.problems.append(f"baseline mIoU: recorded {baseline['miou']}, recomputed {recomputed['miou']}")
        else:
            result.checks.append(f"baseline mIoU reproduced ({recomputed['miou']:.4f})")
    return result
