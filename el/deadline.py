"""The decision's time budget as one object the long loops consult (cooperative checks), and a hard stop.

``Deadline`` reads the injectable clock; ``check`` raises :class:`el.errors.BudgetExceeded` once the budget
is spent or the deadline was cancelled. While a decision runs, its deadline is the *active* one
(``active``, a context variable), so the loops that can run long call :func:`checkpoint` without a
parameter threaded through every signature: the segmenter's frame scales and patch batches, MC dropout's
chunks, the CM's stages and its per-region k-means, the monitor walk. A step between two checkpoints is
not interrupted (a network's forward pass, a PNG decode); ``el.pipeline`` adds the hard stop that returns
the default action at the deadline whatever is running (``run_with_deadline``).
"""

from __future__ import annotations

import contextlib
import contextvars
import threading
from collections.abc import Callable, Iterator
from typing import Any

from el.errors import BudgetExceeded

Clock = Callable[[], float]
_ACTIVE: contextvars.ContextVar[Deadline | None] = contextvars.ContextVar("uav_el_deadline", default=None)


class Deadline:
    """Elapsed time against ``budget_s`` (None: no budget) on ``clock``, from its creation; cancellable."""

    def __init__(self, clock: Clock, budget_s: float | None) -> None:
        self.clock, self.budget_s = clock, budget_s
        self.start = clock()
        self.cancelled = threading.Event()

    def elapsed(self) -> float:
        return self.clock() - self.start

    def remaining(self) -> float | None:
        """Seconds left (may be negative); None without a budget."""
        return None if self.budget_s is None else self.budget_s - self.elapsed()

    def expired(self) -> bool:
        return self.cancelled.is_set() or (self.budget_s is not None and self.elapsed() > self.budget_s)

    def check(self, where: str) -> None:
        """BudgetExceeded naming ``where`` once the budget is spent or the deadline was cancelled."""
        if self.expired():
            raise BudgetExceeded(f"{self._what()} during {where}")

    def ahead(self, next_s: float) -> None:
        """Stop now if the next step, taking about ``next_s`` seconds, would end past the budget."""
        if self.cancelled.is_set() or (self.budget_s is not None and self.elapsed() + max(0.0, next_s) > self.budget_s):
            raise BudgetExceeded(f"{self._what()} (or would be) during monitoring")

    def _what(self) -> str:
        if self.budget_s is None:
            return "decision stopped"
        how = "stopped (hard stop)" if self.cancelled.is_set() else "exceeded"
        return f"time budget of {self.budget_s:g} s {how}"


@contextlib.contextmanager
def active(deadline: Deadline | None) -> Iterator[Deadline | None]:
    """Make ``deadline`` the one :func:`checkpoint` consults in this thread/context for the ``with`` block."""
    token = _ACTIVE.set(deadline)
    try:
        yield deadline
    finally:
        _ACTIVE.reset(token)


def checkpoint(where: str) -> None:
    """A cooperative check inside a long loop: BudgetExceeded when the active deadline has passed; else nothing."""
    deadline = _ACTIVE.get()
    if deadline is not None:
        deadline.check(where)


def run_with_deadline(fn: Callable[[], Any], deadline: Deadline) -> tuple[bool, Any]:
    """Run ``fn`` (with ``deadline`` active) in a worker thread and wait for it at most the deadline's remaining
    wall-clock time: ``(True, result)``, or ``(False, None)`` at the deadline, the deadline then cancelled so
    the worker stops at its next checkpoint. ``fn`` must not raise (the decision loop's does not)."""
    box: dict[str, Any] = {}
    done = threading.Event()
    ctx = contextvars.copy_context()

    def work() -> None:
        try:
            with active(deadline):
                box["result"] = fn()
        finally:
            done.set()

    # not a daemon: at exit the interpreter waits for a stopped worker to reach its next checkpoint, instead of
    # tearing the runtime down under a forward pass (which aborts the process)
    threading.Thread(target=ctx.run, args=(work,), name="uav-el-decision", daemon=False).start()
    remaining = deadline.remaining()
    finished = done.wait(timeout=None if remaining is None else max(0.0, remaining))
    if not finished:
        deadline.cancelled.set()
        return False, None
    return True, box.get("result")
