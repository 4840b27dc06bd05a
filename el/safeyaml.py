"""Loading the YAML a user hands the toolkit (waivers, registries, presets, label sets, hierarchies) within bounds.

``yaml.safe_load`` builds no objects but still expands aliases: a 600-byte file of nested ``*refs`` (an
"alias bomb") becomes a structure whose text is gigabytes once printed. Here aliases are refused outright
(none of the project's files needs one) and a file is refused above :data:`MAX_YAML_BYTES`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

MAX_YAML_BYTES = 1 << 20  # 1 MiB: the largest shipped YAML file is a few tens of kB


class YamlLimitError(yaml.YAMLError):
    """A YAML document outside the limits (an alias, or too large); a YAMLError, so callers' handlers catch it."""


class BoundedSafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` refusing aliases (``*name``): every node is written out once, so size stays linear."""

    def compose_node(self, parent: Any, index: Any) -> Any:  # noqa: D401 - PyYAML's hook
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise YamlLimitError(f"YAML alias *{event.anchor} at line {event.start_mark.line + 1}: aliases are "
                                 "not allowed (write the value out)")
        return super().compose_node(parent, index)


def safe_load(text: str | bytes, *, max_bytes: int = MAX_YAML_BYTES) -> Any:
    """Parse one YAML document like ``yaml.safe_load``, refusing aliases and documents over ``max_bytes``."""
    size = len(text.encode("utf-8")) if isinstance(text, str) else len(text)
    if size > max_bytes:
        raise YamlLimitError(f"YAML document of {size} bytes exceeds the limit of {max_bytes} bytes")
    loader = BoundedSafeLoader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def load_file(path: str | Path, *, max_bytes: int = MAX_YAML_BYTES) -> Any:
    """``safe_load`` of a file, its size checked before it is read (OSError when it cannot be read)."""
    path = Path(path)
    size = path.stat().st_size
    if size > max_bytes:
        raise YamlLimitError(f"{path}: YAML file of {size} bytes exceeds the limit of {max_bytes} bytes")
    return safe_load(path.read_text(encoding="utf-8"), max_bytes=max_bytes)
