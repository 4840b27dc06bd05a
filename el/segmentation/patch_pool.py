"""HD patches under ONNX Runtime on every core at once: one single-threaded session per worker.

A candidate's HD patch is small (a few hundred pixels a side: 1/32 of it is a 10 x 10 map), too small for one
ONNX Runtime session to keep two threads busy: its threads spend much of each operator waiting for one another.
Judging every candidate of a frame (``PatchMonitor.check_many``) gives many such patches at once, and they are
independent: here each worker thread owns a session of one intra-op thread and takes the next patch, largest
first, until none is left. A session computes the same numbers whatever its thread count (ONNX Runtime's CPU
kernels split the outputs among threads, never an output's sum), so each patch gets the scores of a lone pass.

Workers run in copies of the caller's context, so the decision's deadline (``el.base.deadline``) reaches them; the
first error of any worker is raised once every worker has stopped (the others stop at their next patch).
"""

from __future__ import annotations

import contextvars
import threading
from collections.abc import Callable, Sequence
from typing import Any

Job = Callable[[Any], Any]


class PatchPool:
    """``workers`` single-threaded sessions of one ONNX file (``make_engine(threads=1)`` builds each)."""

    def __init__(self, make_engine: Callable[[], Any], workers: int) -> None:
        if workers < 2:
            raise ValueError(f"a patch pool needs at least 2 workers, got {workers}")
        self.engines = [make_engine() for _ in range(workers)]

    def map(self, jobs: Sequence[Job], order: Sequence[int] | None = None) -> list[Any]:
        """``[job(engine) for job in jobs]``, the jobs spread over the workers (taken in ``order``: largest first);
        results in the jobs' order."""
        queue = list(range(len(jobs)) if order is None else order)
        results: list[Any] = [None] * len(jobs)
        errors: list[BaseException] = []
        lock = threading.Lock()

        def work(engine: Any) -> None:
            while True:
                with lock:
                    if errors or not queue:
                        return
                    i = queue.pop(0)
                try:
                    results[i] = jobs[i](engine)
                except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
                    with lock:
                        errors.append(exc)
                    return

        threads = [threading.Thread(target=contextvars.copy_context().run, args=(work, e), daemon=True)
                   for e in self.engines[1:]]
        for t in threads:
            t.start()
        work(self.engines[0])  # the caller is a worker too
        for t in threads:
            t.join()
        if errors:
            raise errors[0]
        return results
