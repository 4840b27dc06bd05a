"""Worker processes bounded by the machine and tied to the process that started them.

``bounded_jobs`` clamps a requested worker count to the CPU cores this process may use (a warning says
so): ``--jobs 1000`` once started about 200 loky workers that wrote nothing in 300 s. ``die_with_parent``,
called in a worker, makes the kernel kill it when its parent dies (Linux ``PR_SET_PDEATHSIG``; elsewhere
a thread that polls the parent's pid), so a SIGKILLed campaign leaves no worker writing shards.
``dask_map`` runs tasks on dask.distributed: a local cluster's workers are the campaign's children and get
the same guard (dask's own watchdog, a thread that needs the GIL to exit, is then a second line).
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import Any

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
POLL_S = 1.0  # the pid watchdog's period where prctl is not available


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one, else ``os.cpu_count()``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def bounded_jobs(jobs: int, *, what: str = "--jobs", warn: Callable[[str], None] | None = None) -> int:
    """``jobs`` clamped to the usable cores; when it was larger, ``warn`` (default: a RuntimeWarning) gets one
    line naming both. ValueError below 1."""
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"{what} must be an integer >= 1, got {jobs!r}")
    cores = usable_cores()
    if jobs > cores:
        message = f"{what} {jobs} exceeds the {cores} CPU core(s) this process may use; using {cores} worker(s)"
        if warn is None:
            warnings.warn(message, RuntimeWarning, stacklevel=2)
        else:
            warn(message)
        return cores
    return jobs


def die_with_parent(parent_pid: int | None) -> None:
    """In a worker started by ``parent_pid``: be killed when that process dies; exit now if it already has.

    Idempotent and cheap (call it at the start of every task). None or our own pid: nothing to do."""
    if parent_pid is None or parent_pid == os.getpid():
        return
    if _STATE.get("parent") == parent_pid:
        return
    _STATE["parent"] = parent_pid
    if not _set_pdeathsig():
        threading.Thread(target=_watch, args=(parent_pid,), daemon=True, name="uav-el-parent-watch").start()
    if os.getppid() != parent_pid:  # the parent died before the guard was set: nothing will reap us
        os._exit(1)


_STATE: dict[str, int] = {}


def _set_pdeathsig() -> bool:
    """Ask Linux to SIGKILL this process when its parent dies; False where that is not available."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):  # pragma: no cover - no libc prctl
        return False


def _watch(parent_pid: int) -> None:  # pragma: no cover - the fallback off Linux
    while os.getppid() == parent_pid:
        time.sleep(POLL_S)
    os._exit(1)


DIRECT_CHILD_METHODS = ("spawn", "fork")
"""dask's worker start methods (``distributed.worker.multiprocessing-method``) whose workers are the children of
the process that started the cluster; with ``forkserver`` they are the fork server's, so no pid is passed."""


def dask_parent_pid(scheduler: str | None) -> int | None:
    """The pid dask workers must die with: this process for a local cluster whose workers are its children;
    None for a running scheduler's workers (``--scheduler``: not ours to end) or a fork server's."""
    if scheduler:
        return None
    import dask

    method = dask.config.get("distributed.worker.multiprocessing-method", "spawn")
    return os.getpid() if method in DIRECT_CHILD_METHODS else None


def dask_logging_follows_ours() -> None:
    """dask's loggers (``distributed.*``) at this process's level (WARNING by default, INFO at ``-v``, ERROR at
    ``-q``), here and in the worker processes a local cluster starts (they read ``DASK_LOGGING__DISTRIBUTED``
    when they import dask); a level the user set in that variable wins."""
    level = logging.getLevelName(max(logging.getLogger().getEffectiveLevel(), logging.DEBUG))
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", str(level).lower())
    import distributed  # noqa: F401  (sets up its loggers at import: set their level after)

    try:
        logging.getLogger("distributed").setLevel(os.environ["DASK_LOGGING__DISTRIBUTED"].upper())
    except ValueError:  # not a level name: dask's own reading of the variable stands
        pass


def dask_map(fn: Callable[..., Any], items: Iterable[Any], *, jobs: int, scheduler: str | None,
             **kwargs: Any) -> Iterator[Any]:
    """``fn(item, parent_pid=..., **kwargs)`` for every item on dask.distributed (a running ``scheduler``, else a
    local cluster of ``jobs`` one-thread worker processes), results as they complete. ``fn`` calls
    :func:`die_with_parent` with ``parent_pid``."""
    dask_logging_follows_ours()
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:  # no dashboard; the scheduler's own HTTP routes on a free local port, not 8787
        cluster = LocalCluster(n_workers=max(1, jobs), threads_per_worker=1, processes=True,
                               dashboard_address=None, scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
        client = Client(cluster)
    try:
        futures = client.map(fn, list(items), parent_pid=dask_parent_pid(scheduler), pure=False, **kwargs)
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
