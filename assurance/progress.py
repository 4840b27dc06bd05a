"""Progress bars for long commands: shown on a terminal, quiet one-line summaries otherwise."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(items: Iterable[T], *, total: int | None = None, desc: str = "", enabled: bool = True) -> Iterator[T]:
    """Wrap an iterable in a tqdm bar on stderr (plain text updates when stderr is not a terminal)."""
    if not enabled:
        yield from items
        return
    yield from tqdm(items, total=total, desc=desc, file=sys.stderr, dynamic_ncols=True,
                    mininterval=0.5 if sys.stderr.isatty() else 5.0, leave=True)
