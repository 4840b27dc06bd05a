"""Progress of long commands: a tqdm bar on a terminal; elsewhere (a CI log, a file) plain lines.

tqdm redraws its bar with carriage returns, which a log that is not a terminal keeps as one long line or as many
partial ones. When stderr is not a terminal, :func:`progress` prints instead one plain line at each tenth of the
work (:data:`EVERY_FRACTION`) or every :data:`EVERY_S` seconds, whichever comes first, and one at the end:
``campaign: 12/60 (20%), 31 s``. ``UAV_EL_PROGRESS=bar|lines|none`` forces a style (``none``: no progress at all);
``enabled=False`` (a command's ``-q``) prints nothing.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TextIO, TypeVar

T = TypeVar("T")
ENV = "UAV_EL_PROGRESS"
STYLES = ("bar", "lines", "none")
EVERY_FRACTION = 0.1
EVERY_S = 30.0


def style(stream: TextIO | None = None) -> str:
    """``bar`` on a terminal, else ``lines``; ``$UAV_EL_PROGRESS`` wins when it names a style."""
    forced = os.environ.get(ENV, "").strip().lower()
    if forced in STYLES:
        return forced
    stream = sys.stderr if stream is None else stream
    try:
        return "bar" if stream.isatty() else "lines"
    except (AttributeError, ValueError):  # a closed or odd stream: no bar
        return "lines"


def progress(items: Iterable[T], *, total: int | None = None, desc: str = "", enabled: bool = True) -> Iterator[T]:
    """Wrap an iterable: a tqdm bar on stderr on a terminal, plain periodic lines otherwise (see the module)."""
    chosen = style() if enabled else "none"
    if chosen == "none":
        yield from items
        return
    if chosen == "bar":
        from tqdm import tqdm

        yield from tqdm(items, total=total, desc=desc, file=sys.stderr, dynamic_ncols=True, mininterval=0.5,
                        leave=True)
        return
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    yield from plain_lines(items, total=total, desc=desc)


def plain_lines(items: Iterable[T], *, total: int | None, desc: str = "", stream: TextIO | None = None,
                clock: Callable[[], float] = time.monotonic, every_s: float = EVERY_S,
                every_fraction: float = EVERY_FRACTION) -> Iterator[T]:
    """``items``, printing ``desc: done/total (pct%), elapsed`` each ``every_fraction`` of ``total`` or each
    ``every_s`` seconds (whichever first), and a last line when the items end."""
    out = sys.stderr if stream is None else stream
    start = last = clock()
    step = max(1, int(total * every_fraction)) if total else None
    done = 0
    next_at = step
    for item in items:
        yield item
        done += 1
        now = clock()
        if (next_at is not None and done >= next_at and done != total) or now - last >= every_s:
            _line(out, desc, done, total, now - start)
            last = now
            while next_at is not None and next_at <= done:
                next_at += step  # type: ignore[operator]
    _line(out, desc, done, total, clock() - start)


def _line(out: TextIO, desc: str, done: int, total: int | None, elapsed: float) -> None:
    of = f"/{total} ({100 * done // total}%)" if total else ""
    print(f"{desc or 'progress'}: {done}{of}, {elapsed:.0f} s", file=out, flush=True)
