"""Training checkpoints: where they live, writing and reading them, and what a resumed run may not change."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import torch

from assurance.files import atomic_write_bytes
from assurance.fitting.network.train_config import TrainConfig
from el.segmentation.architectures import default_arch


def checkpoint_path(weights_path: str | Path) -> Path:
    """Where training keeps its resumable state: ``<weights>.ckpt``."""
    return Path(weights_path).with_suffix(".ckpt")


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """Write a training checkpoint atomically (``torch.save`` to memory, then temp file + rename)."""
    buf = io.BytesIO()
    torch.save(state, buf)
    atomic_write_bytes(path, buf.getvalue())


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """A training checkpoint (``weights_only`` loading); ValueError naming the file if unusable."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no checkpoint to resume from")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # corrupt or foreign file
        raise ValueError(f"{path}: unreadable checkpoint: {exc}") from exc
    for key in ("step", "model", "optimizer", "scheduler", "config", "data"):
        if key not in state:
            raise ValueError(f"{path}: checkpoint has no {key!r}")
    return state


def _with_defaults(old: dict[str, Any], defaults: dict[str, Any]) -> dict[str, Any]:
    """``old`` with the keys it lacks (at any depth) taken from ``defaults``."""
    out = {**{k: v for k, v in defaults.items() if k not in old}, **old}
    for k, v in defaults.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _with_defaults(out[k], v)
    return out


def config_changes(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """``key: old -> new`` for each setting a resumed run changes (a key added since the checkpoint: its default)."""
    defaults = TrainConfig().to_dict()
    defaults["arch"] = default_arch((old.get("arch") or {}).get("name", "msdlite")).to_dict()
    old = _with_defaults(old, defaults)
    keys = sorted(set(old) | set(new))
    return [f"{k}: {old.get(k)!r} -> {new.get(k)!r}" for k in keys
            if k not in ("checkpoint_every",) and old.get(k) != new.get(k)]
