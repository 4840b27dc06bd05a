"""The segmentation architectures a model card can name, and building one from its card entry.

``msdlite``: :class:`el.segmentation.model.MSDLite`, the compact CNN trained from scratch;
``lite0``: :class:`el.segmentation.lite.LiteSeg`, an ImageNet-pretrained EfficientNet-Lite0 encoder
with an FPN decoder. A card's ``architecture`` dict carries ``name``; a card without it is MSDLite.
"""

from __future__ import annotations

from typing import Any

from torch import nn

from el.segmentation.lite import LiteConfig, LiteSeg
from el.segmentation.model import ArchConfig, MSDLite

ARCHITECTURES: dict[str, tuple[type, type[nn.Module]]] = {
    "msdlite": (ArchConfig, MSDLite),
    "lite0": (LiteConfig, LiteSeg),
}
AnyArch = ArchConfig | LiteConfig


def arch_names() -> list[str]:
    return list(ARCHITECTURES)


def arch_from_dict(data: dict[str, Any]) -> AnyArch:
    """The architecture config of a card's ``architecture`` entry; ValueError for an unknown name."""
    if not isinstance(data, dict):
        raise ValueError(f"architecture must be a JSON object, got {type(data).__name__}")
    name = data.get("name", "msdlite")
    if name not in ARCHITECTURES:
        raise ValueError(f"unknown architecture {name!r} (known: {', '.join(ARCHITECTURES)})")
    return ARCHITECTURES[name][0].from_dict(data)


def default_arch(name: str) -> AnyArch:
    """The default configuration of the architecture called ``name``."""
    if name not in ARCHITECTURES:
        raise ValueError(f"unknown architecture {name!r} (known: {', '.join(ARCHITECTURES)})")
    return ARCHITECTURES[name][0]()


def build_model(config: AnyArch | dict[str, Any] | None = None) -> nn.Module:
    """An untrained network from a config (or its dict form, as stored in a model card; None: MSDLite)."""
    if config is None:
        config = ArchConfig()
    elif isinstance(config, dict):
        config = arch_from_dict(config)
    for config_type, model_type in ARCHITECTURES.values():
        if isinstance(config, config_type):
            return model_type(config)
    raise ValueError(f"not an architecture config: {type(config).__name__}")
