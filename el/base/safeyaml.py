"""Loading the YAML a user hands the toolkit (waivers, registries, presets, label sets, hierarchies) within bounds.

``yaml.safe_load`` builds no objects but still expands aliases: a 600-byte file of nested ``*refs`` (an
"alias bomb") becomes a structure whose text is gigabytes once printed. Here aliases are refused outright
(none of the project's files needs one), a document is refused above :data:`MAX_YAML_BYTES` or nested deeper than
``el.base.userfiles.MAX_DEPTH`` (PyYAML composes recursively: ``[[[[...`` thousands deep exhausts the stack), and a file
is read through ``el.base.userfiles`` (a regular file only, its size capped before and while it is read).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from el.base import userfiles

MAX_YAML_BYTES = userfiles.MAX_SETTINGS_BYTES  # 1 MiB: the largest shipped YAML file is a few tens of kB


class YamlLimitError(yaml.YAMLError, ValueError):
    """A YAML document or file outside the limits (an alias, too large, too deep, not a regular file); a YAMLError
    and a ValueError, so callers' handlers of either catch it."""


class BoundedSafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` refusing aliases (``*name``): every node is written out once, so size stays linear."""

    def compose_node(self, parent: Any, index: Any) -> Any:  # noqa: D401 - PyYAML's hook
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise YamlLimitError(f"YAML alias *{event.anchor} at line {event.start_mark.line + 1}: aliases are "
                                 "not allowed (write the value out)")
        return super().compose_node(parent, index)


def safe_load(text: str | bytes, *, max_bytes: int = MAX_YAML_BYTES,
              loader: type[BoundedSafeLoader] | None = None) -> Any:
    """Parse one YAML document like ``yaml.safe_load``, refusing aliases, documents over ``max_bytes`` and
    documents nested deeper than ``el.base.userfiles.MAX_DEPTH``; ``loader``: a subclass of :class:`BoundedSafeLoader`
    (default: it)."""
    size = len(text.encode("utf-8")) if isinstance(text, str) else len(text)
    if size > max_bytes:
        raise YamlLimitError(f"YAML document of {size} bytes exceeds the limit of {max_bytes} bytes")

    def parse(source: str | bytes) -> Any:
        parser = (loader or BoundedSafeLoader)(source)
        try:
            return parser.get_single_data()
        finally:
            parser.dispose()

    try:
        return userfiles.parse_bounded(parse, text, where="YAML document")  # type: ignore[arg-type]
    except userfiles.UserFileError as exc:
        raise YamlLimitError(str(exc)) from None


def load_file(path: str | Path, *, max_bytes: int = MAX_YAML_BYTES, what: str = "YAML file",
              within: str | Path | None = None, loader: type[BoundedSafeLoader] = BoundedSafeLoader) -> Any:
    """``safe_load`` of a file read through ``el.base.userfiles.read_text`` (a regular file, at most ``max_bytes``,
    inside ``within`` when given): ``YamlLimitError`` naming the file when it cannot be read or is outside the
    limits, ``YAMLError`` when it does not parse. ``loader``: a subclass of :class:`BoundedSafeLoader` (e.g. one
    that keeps dates as text)."""
    try:
        text = userfiles.read_text(path, what=what, max_bytes=max_bytes, within=within)
    except userfiles.UserFileError as exc:
        raise YamlLimitError(str(exc)) from None
    return safe_load(text, max_bytes=max_bytes, loader=loader)
