"""Which segmentation network a fitted record (learned monitor, out-of-domain gate, calibration card) rests on.

The record stores the network's weights hash as the network reports it (``weights_sha256``), never the hash
of a file that happens to lie at the default path: the flight code refuses a record on any other network.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from assurance.paths import shown_path
from el.segmentation.contract import weights_sha256_of
from el.segmentation.factory import is_weights_file
from el.segmentation.weights import DEFAULT_WEIGHTS


def network_record(segmenter: Any, weights: str | Path | None = None, *, loaded: bool = True) -> dict[str, Any]:
    """``{"path", "sha256", "segmenter"}`` of the network a record is fitted on.

    ``weights``: the model spec the segmenter was loaded from (None: the shipped weights); ``loaded``: False
    when the caller built the segmenter itself (no file to name).
    """
    sha = weights_sha256_of(segmenter)
    path: Path | None = None
    if loaded:
        path = DEFAULT_WEIGHTS if weights is None else (Path(weights) if is_weights_file(weights) else None)
    return {"path": shown_path(path) if path is not None else None, "sha256": sha,
            "segmenter": "weights" if sha else type(segmenter).__name__}
