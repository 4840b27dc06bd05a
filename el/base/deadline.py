"""The decision's time budget as one object the long loops consult (cooperative checks), a hard stop, and the
cancellation of a step in flight.

``Deadline`` reads the injectable clock; ``check`` raises :class:`el.base.errors.BudgetExceeded` once the budget
is spent or the deadline was cancelled. While a decision runs, its deadline is the *active* one
(``active``, a context variable), so the loops that can run long call :func:`checkpoint` without a
parameter threaded through every signature: the segmenter's frame scales and patch batches, MC dropout's
chunks, the CM's stages and its per-region k-means, the monitor walk. A step between two checkpoints is
not interrupted by them (a network's forward pass, a PNG decode); ``el.flight.pipeline`` adds the hard stop that returns
the default action at the deadline whatever is running (``run_with_deadline``).

So that the stopped work does not go on computing after that answer, a step whose engine can be
cancelled runs inside :func:`stop_at_deadline`: its ``stop`` is called from another thread at the deadline (a
``threading.Timer`` armed at the remaining budget, on a wall clock only: an injected clock's seconds are not the
timer's) or when the deadline is cancelled (the hard stop), and the step then raises ``BudgetExceeded``. ONNX
Runtime runs are cancelled so (``RunOptions.terminate``, ``el.segmentation.onnx_engine.run_session``); a torch
forward pass cannot be, and runs to its end: the remaining worst case after the deadline is one forward pass (a
frame scale, one padded-size patch batch, one MC-dropout chunk), after which the next checkpoint stops the
decision. The stop acts only past the deadline, when the decision is ``timeout`` whatever the step would have
returned, so a decision within its budget is the one without it (nothing armed changes a number).
"""

from __future__ import annotations

import contextlib
import contextvars
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from el.base.errors import BudgetExceeded

Clock = Callable[[], float]
DEFAULT_TIME_BUDGET_S = 10.0
"""A decision's time budget in seconds where its system states none ([targets] time_budget_s)."""
_ACTIVE: contextvars.ContextVar[Deadline | None] = contextvars.ContextVar("uav_el_deadline", default=None)
WALL_CLOCKS: tuple[Clock, ...] = (time.perf_counter, time.monotonic)
"""Clocks whose seconds a ``threading.Timer`` keeps (monotonic, real time): only on them is a stop armed by time."""
TIMER_SLACK_S = 0.001  # a stop's timer fires this long after the deadline, so the clock has passed it too


class Deadline:
    """Elapsed time against ``budget_s`` (None: no budget) on ``clock``, from its creation; cancellable."""

    def __init__(self, clock: Clock, budget_s: float | None) -> None:
        self.clock, self.budget_s = clock, budget_s
        self.start = clock()
        self.cancelled = threading.Event()
        self._stops: dict[object, Callable[[], None]] = {}  # the steps in flight that can be cancelled (stopping)
        self._lock = threading.Lock()

    @property
    def wall(self) -> bool:
        """Whether the clock is a wall clock (:data:`WALL_CLOCKS`), whose remaining seconds a timer can wait for."""
        return any(self.clock is c for c in WALL_CLOCKS)

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

    def cancel(self) -> None:
        """Cancel the deadline (the hard stop): every later check raises, and the steps in flight are stopped."""
        self.cancelled.set()
        with self._lock:
            for stop in self._stops.values():
                stop()

    @contextlib.contextmanager
    def stopping(self, stop: Callable[[], None], where: str) -> Iterator[None]:
        """Run the ``with`` block (one step, at ``where``) with ``stop`` armed: called once, from another thread, when
        the deadline passes during the block (a timer at the remaining budget, on a wall clock) or is cancelled;
        never after the block ends. The block does not start past the deadline (BudgetExceeded)."""
        self.check(where)
        key = object()  # this step's (kept alive by its timer: never another step's)
        fired: list[bool] = []

        def once() -> None:  # under self._lock
            if key in self._stops and not fired:
                fired.append(True)
                stop()

        with self._lock:
            self._stops[key] = once
        remaining = self.remaining() if self.wall else None
        timer = None
        if remaining is not None:
            timer = threading.Timer(max(0.0, remaining) + TIMER_SLACK_S, self._fire, args=(key,))
            timer.daemon = True
            timer.name = "uav-el-deadline"
            timer.start()
        try:
            if self.cancelled.is_set():  # cancelled between the check and the registration
                self._fire(key)
            yield
        finally:
            if timer is not None:
                timer.cancel()
            with self._lock:
                self._stops.pop(key, None)

    def _fire(self, key: object) -> None:
        with self._lock:
            stop = self._stops.get(key)
            if stop is not None:
                stop()

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


@contextlib.contextmanager
def stop_at_deadline(stop: Callable[[], None], where: str) -> Iterator[bool]:
    """:meth:`Deadline.stopping` of the active deadline around one cancellable step; yields whether one is armed
    (False, and nothing armed, without an active deadline: campaigns, probes, calls outside a decision)."""
    deadline = _ACTIVE.get()
    if deadline is None:
        yield False
        return
    with deadline.stopping(stop, where):
        yield True


def run_with_deadline(fn: Callable[[], Any], deadline: Deadline) -> tuple[bool, Any]:
    """Run ``fn`` (with ``deadline`` active) in a worker thread and wait for it at most the deadline's remaining
    wall-clock time: ``(True, result)``, or ``(False, None)`` at the deadline, the deadline then cancelled so
    the worker stops at its next checkpoint, and a cancellable step in flight at once (:meth:`Deadline.cancel`).
    ``fn`` must not raise (the decision loop's does not)."""
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
        deadline.cancel()
        return False, None
    return True, box.get("result")
