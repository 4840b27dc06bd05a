"""Weights files and their model cards: check the SHA-256 before loading.

Writing them is ``assurance.fitting.network.weights_io``.

A weights file ``NAME.pt`` is a float32 ``state_dict`` written with ``torch.save``. Next to it,
``NAME.json`` is its model card: the file's SHA-256, the architecture hyper-parameters needed to
rebuild the network, and (after training) the data hashes, seeds and validation figures.

Loading reads the file once, checks its SHA-256 against the card, and only then deserialises it with
``torch.load(..., weights_only=True)`` (no pickled code is ever executed). Every problem raises
:class:`WeightsError` naming the file.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from el.base import userfiles
from el.base.errors import WeightsError
from el.base.hashing import sha256_bytes, sha256_file  # noqa: F401  (re-exported)
from el.base.torch_extra import require_torch

if TYPE_CHECKING:
    import torch

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "model.pt"
CARD_FORMAT = "uav-el-segmentation-card/1"


def card_path(weights_path: str | Path) -> Path:
    """The model card (JSON sidecar) of a weights file: same name, ``.json`` suffix."""
    return Path(weights_path).with_suffix(".json")




def read_card(weights_path: str | Path) -> dict[str, Any]:
    """The model card of a weights file; WeightsError if missing or malformed."""
    path = card_path(weights_path)
    if not path.is_file():
        raise WeightsError(f"{path}: model card not found (expected next to {Path(weights_path).name})")

    try:  # bounded: a link to /proc or a device, a file over 64 MiB is refused unread
        card = json.loads(userfiles.read_text(path, what="model card", max_bytes=userfiles.MAX_RECORD_BYTES))
    except userfiles.UserFileError as exc:
        raise WeightsError(str(exc)) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise WeightsError(f"{path}: unreadable model card: {exc}") from exc
    if not isinstance(card, dict):
        raise WeightsError(f"{path}: model card must be a JSON object")
    if card.get("format") != CARD_FORMAT:
        raise WeightsError(f"{path}: unknown model card format {card.get('format')!r} (expected {CARD_FORMAT!r})")
    for key in ("weights_sha256", "architecture"):
        if key not in card:
            raise WeightsError(f"{path}: model card has no {key!r}")
    return card


def checked_weights(weights_path: str | Path | None = None) -> tuple[Path, bytes, dict[str, Any]]:
    """The weights file's path, bytes and card, its SHA-256 checked against the card (torch is not needed)."""
    path = Path(weights_path) if weights_path is not None else DEFAULT_WEIGHTS
    if not path.exists():
        hint = " (train one with `uav-el train`)" if weights_path is None else ""
        raise WeightsError(f"{path}: weights file not found{hint}")
    if not path.is_file():
        raise WeightsError(f"{path}: not a file")
    card = read_card(path)

    try:  # bounded: a link to /proc/self/pagemap is a "regular file" that reads for hundreds of GB
        data = userfiles.read_bytes(path, what="weights file", max_bytes=userfiles.MAX_MODEL_BYTES,
                                    hard_links=True)  # bytes that are hashed and decoded as tensors, never text
    except userfiles.UserFileError as exc:
        raise WeightsError(str(exc)) from None
    digest = sha256_bytes(data)
    if digest != card["weights_sha256"]:
        raise WeightsError(
            f"{path}: SHA-256 mismatch: file has {digest}, {card_path(path).name} records "
            f"{card['weights_sha256']} (the weights were altered or replaced)"
        )
    return path, data, card


def _unpickling_reason(exc: Exception) -> str:
    """Why torch refused a file, without torch's advice to retry with ``weights_only=False`` (never do:
    that would run the pickled code this check exists to refuse)."""
    import pickle

    text = str(exc)
    if isinstance(exc, pickle.UnpicklingError) or "weights_only" in text:
        keep = [ln.strip() for ln in text.splitlines() if ln.strip() and "weights_only" not in ln
                and "trusted source" not in ln and "documentation" not in ln]
        detail = keep[0] if keep else type(exc).__name__
        return f"refused: the file holds pickled objects that are not plain tensors ({detail})"
    return text


def load_weights(weights_path: str | Path | None = None, *, device: str | torch.device = "cpu"
                 ) -> tuple[torch.nn.Module, dict[str, Any]]:
    """Rebuild the network from a weights file after checking its SHA-256 against its card.

    Returns ``(model in eval mode, card)``. Raises WeightsError when the weights file or its card
    is missing, the hash does not match, or the state dict does not fit the recorded architecture.
    """
    torch = require_torch("loading a .pt weights file")  # torch: the optional heavy dependency, imported only here
    from el.segmentation.architectures import build_model  # deferred: imports torch at load (the train extra)

    path, data, card = checked_weights(weights_path)
    try:
        state = torch.load(io.BytesIO(data), map_location=device, weights_only=True)
    except Exception as exc:  # torch raises several types for corrupt or unsafe files
        raise WeightsError(f"{path}: cannot load the state dict (weights_only): {_unpickling_reason(exc)}") from exc
    if not isinstance(state, dict):
        raise WeightsError(f"{path}: expected a state dict, got {type(state).__name__}")
    try:
        model = build_model(card["architecture"])
    except (TypeError, ValueError) as exc:
        raise WeightsError(f"{card_path(path)}: invalid architecture: {exc}") from exc
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        first = str(exc).splitlines()[0]
        raise WeightsError(f"{path}: state dict does not fit the recorded architecture: {first}") from exc
    return model.to(device).eval(), card
