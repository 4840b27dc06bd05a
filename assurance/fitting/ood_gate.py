"""Fitting the out-of-domain frame gate (``el.monitors.ood``) and reporting its scores under perturbations.

:func:`fit_ood` embeds the clean frames of the train split, fits their mean and a shrunk covariance
(``sklearn.covariance.LedoitWolf``: well conditioned even with fewer frames than dimensions) and sets
the threshold at a stated quantile (default 99.5%) of the validation frames' distances, so about
0.5% of in-domain frames would be sent to the default action. :func:`ood_shift_report` measures the
distances on scenes as they are and under each campaign perturbation (a table and a plot): what the
gate sees of fog, noise or blur at a severity.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from assurance.campaign.perturbations import PAPER_PERTURBATIONS, TRAITS, perturb
from assurance.fitting.learned_monitor import split_sha256
from assurance.paths import shown_path
from assurance.scenes.uavid import Sample, iter_samples, read_image
from el.monitors.ood import OODGate, embedding_kind, frame_embedding, ood_document

DEFAULT_QUANTILE = 0.995


def _samples(data: str | Path, images: int | None) -> list[Sample]:
    samples = list(iter_samples(data, require_labels=False))[:images]
    if not samples:
        raise ValueError(f"{data}: no scenes")
    return samples


def embed_frames(data: str | Path, segmenter: Any, *, kind: str | None = None, images: int | None = None,
                 perturbation: str = "none", severity: int = 3, seed: int = 0, progress: bool = False,
                 desc: str = "frames") -> np.ndarray:
    """Embeddings (n, d) of the frames of ``data``, perturbed as a campaign would (seeded per frame); ``progress``
    shows a bar on stderr."""
    from assurance.progress import progress as bar

    rows = []
    samples = _samples(data, images)
    for i, s in enumerate(bar(samples, total=len(samples), desc=desc, enabled=progress)):
        rgb = read_image(s.image_path)
        if perturbation != "none":
            rgb = perturb(rgb, perturbation, severity, np.random.default_rng([seed, i]))
        rows.append(frame_embedding(segmenter, rgb, kind=kind))
    return np.asarray(rows, np.float64)


def fit_ood_body(train: np.ndarray, val: np.ndarray, *, kind: str, quantile: float = DEFAULT_QUANTILE,
                 **record: Any) -> dict[str, Any]:
    """Mean and Ledoit-Wolf precision of ``train`` (n, d), threshold at ``quantile`` of ``val``'s distances."""
    import sklearn
    from sklearn.covariance import LedoitWolf

    if not 0.0 < quantile < 1.0:
        raise ValueError(f"quantile must lie in (0, 1), got {quantile!r}")
    if train.shape[0] < 2 or val.shape[0] < 1:
        raise ValueError(f"{train.shape[0]} training and {val.shape[0]} validation frames: need >= 2 and >= 1")
    lw = LedoitWolf().fit(train)
    body = {"embedding": kind, "dims": int(train.shape[1]), "mean": lw.location_.tolist(),
            "precision": lw.precision_.tolist(), "shrinkage": float(lw.shrinkage_), "quantile": float(quantile),
            "threshold": 0.0, "sklearn_version": sklearn.__version__,
            "created": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"), **record}
    gate = OODGate("<fit>", "", body, lw.location_, lw.precision_)
    d_val = np.array([gate.distance(x) for x in val])
    body["threshold"] = float(np.quantile(d_val, quantile))
    body["validation_distances"] = {"frames": int(d_val.size), "median": float(np.median(d_val)),
                                    "max": float(d_val.max())}
    return body


def fit_ood(data: str | Path, val: str | Path, segmenter: Any, *, quantile: float = DEFAULT_QUANTILE,
            images: int | None = None, weights: dict[str, Any] | None = None, progress: bool = False) -> dict[str, Any]:
    """Fit the gate on the frames of ``data``, threshold on ``val``: the JSON document (``uav-el fit-ood``).

    ``weights``: the network record (default: the one ``segmenter`` reports; ValueError if it reports none)."""
    from assurance.fitting.network_identity import network_record

    weights = weights if weights is not None else network_record(segmenter, loaded=False)
    kind = embedding_kind(segmenter)
    train = embed_frames(data, segmenter, kind=kind, images=images, progress=progress, desc="training frames")
    held = embed_frames(val, segmenter, kind=kind, images=images, progress=progress, desc="validation frames")
    body = fit_ood_body(train, held, kind=kind, quantile=quantile, weights=weights,
                        training={"path": shown_path(data), "frames": int(train.shape[0]),
                                  "sha256": split_sha256(_samples(data, images), data, labels=False)},
                        validation={"path": shown_path(val), "frames": int(held.shape[0]),
                                    "sha256": split_sha256(_samples(val, images), val, labels=False)})
    return ood_document(body)


def ood_shift_report(gate: OODGate, data: str | Path, segmenter: Any, *, out: str | Path | None = None,
                     perturbations: Sequence[str] = PAPER_PERTURBATIONS, severity: int = 3,
                     images: int | None = None, seed: int = 0) -> list[dict[str, Any]]:
    """Distance distribution of the scenes of ``data`` as they are and under each perturbation.

    Returns one row per perturbation (frames, median, 95th percentile, max, share above the gate's
    threshold); with ``out``, writes ``ood_shift.csv``, ``ood_shift.md`` and ``ood_shift.png``.
    """
    names = ["none", *[p for p in perturbations if p != "none"]]
    dists = {}
    for name in names:
        x = embed_frames(data, segmenter, kind=gate.kind, images=images, perturbation=name, severity=severity,
                         seed=seed)
        dists[name] = np.array([gate.distance(v) for v in x])
    t = gate.threshold
    rows = [{"perturbation": n, "severity": severity if TRAITS[n].graded else 0, "frames": int(d.size),
             "median": float(np.median(d)), "p95": float(np.quantile(d, 0.95)), "max": float(d.max()),
             "above_threshold": float((d > t).mean())} for n, d in dists.items()]
    if out is not None:
        _write_report(Path(out), rows, dists, t)
    return rows


def _write_report(out: Path, rows: list[dict[str, Any]], dists: dict[str, np.ndarray], threshold: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    cols = list(rows[0])
    (out / "ood_shift.csv").write_text("\n".join([",".join(cols)] + [",".join(f"{r[c]}" for c in cols)
                                                                    for r in rows]) + "\n")
    fmt = {"median": ".3g", "p95": ".3g", "max": ".3g", "above_threshold": ".1%"}
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(format(r[c], fmt.get(c, "")) for c in cols) + " |" for r in rows]
    (out / "ood_shift.md").write_text(f"Out-of-domain distance (threshold {threshold:.4g})\n\n" + "\n".join(lines)
                                      + "\n")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.boxplot(list(dists.values()), tick_labels=list(dists))
    ax.axhline(threshold, color="tab:red", linestyle="--", label=f"threshold {threshold:.3g}")
    ax.set_ylabel("Mahalanobis distance")
    ax.set_yscale("log")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "ood_shift.png", dpi=120)
    plt.close(fig)
