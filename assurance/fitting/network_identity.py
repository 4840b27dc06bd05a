"""Which segmentation network a fitted record (learned monitor, out-of-domain gate, calibration card) rests on.

The record stores the network's weights hash as the network reports it (``weights_sha256``), never the hash
of a file that happens to lie at the default path: the flight code refuses a record on any other network.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from assurance.paths import shown_path
from el.segmentation.contract import weights_sha256_of
from el.segmentation.factory import FILE, PLUGIN, SHIPPED_KIND, model_kind
from el.segmentation.weights import DEFAULT_WEIGHTS


def network_record(segmenter: Any, weights: str | Path | dict[str, Any] | None = None, *,
                   loaded: bool = True) -> dict[str, Any]:
    """``{"path", "sha256", "segmenter"}`` of the network a record is fitted on (``"model"`` too for a model
    registered by name). ValueError for a network that reports no weights hash: the record could not be
    bound to it, and the flight code refuses unbound records.

    ``weights``: the model spec the segmenter was loaded from (None: the shipped weights); ``loaded``: False
    when the caller built the segmenter itself (no file to name).
    """
    sha = weights_sha256_of(segmenter)
    if not sha:
        raise ValueError(f"the segmentation model ({type(segmenter).__name__}) reports no weights_sha256: a fitted "
                         f"record could not be bound to it; give the model an identity (its weights hash)")
    if isinstance(weights, dict):  # a system file's model: its file (if any) and kind
        return {"path": weights.get("path"), "sha256": sha, "segmenter": "weights", "model": weights.get("kind")}
    kind = model_kind(weights) if loaded else None
    path = DEFAULT_WEIGHTS if kind == SHIPPED_KIND else (Path(weights) if kind == FILE else None)
    record = {"path": shown_path(path) if path is not None else None, "sha256": sha, "segmenter": "weights"}
    if kind == PLUGIN:
        record["model"] = str(weights)
    return record
