"""Writing a weights file and its model card (read and checked by ``el.segmentation.weights``), atomically."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import torch

from assurance.files import atomic_write_bytes
from el.base.hashing import sha256_bytes
from el.segmentation.model import count_parameters
from el.segmentation.weights import CARD_FORMAT, card_path


def state_dict_bytes(model: torch.nn.Module) -> bytes:
    """The model's float32 CPU state dict, serialised as ``torch.save`` writes it."""
    state = {k: (v.detach().to("cpu", torch.float32) if v.is_floating_point() else v.detach().cpu())
             for k, v in model.state_dict().items()}
    buf = io.BytesIO()
    torch.save(state, buf)
    return buf.getvalue()


def write_card(weights_path: str | Path, card: dict[str, Any]) -> Path:
    """Write the model card next to the weights (atomically); returns its path."""
    path = card_path(weights_path)
    text = json.dumps(card, indent=2, allow_nan=False) + "\n"
    atomic_write_bytes(path, text.encode("utf-8"))
    return path


def save_weights(model: torch.nn.Module, weights_path: str | Path,
                 card: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write the weights file and its card; returns the card as written.

    The card gets ``format``, ``weights_file``, ``weights_sha256``, ``architecture`` and
    ``parameters`` filled in from the model; other keys of ``card`` are kept as given.
    """
    weights_path = Path(weights_path)
    data = state_dict_bytes(model)
    atomic_write_bytes(weights_path, data)
    full = {
        "format": CARD_FORMAT,
        "weights_file": weights_path.name,
        "weights_sha256": sha256_bytes(data),
        "weights_bytes": len(data),
        "architecture": model.config.to_dict(),
        "parameters": count_parameters(model),
    }
    for key, value in (card or {}).items():
        if key not in full:
            full[key] = value
    write_card(weights_path, full)
    return full
