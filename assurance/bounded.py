"""Run an applicant's work in a child process with a time and a memory limit: its report templates
(``assurance.evidence.render``), the re-run of its network (``assurance.requirements.determinism``).

Jinja2's sandbox keeps a template away from Python's internals, not from the machine's resources: two nested
``range(100000)`` loops never end, ``('x' * 10**10) | length`` asks for 10 GB, a template including itself
recurses until Python stops it; an ONNX graph can loop without end. The work runs in a child whose address space is
capped (``RLIMIT_AS``: what it has at the start plus :data:`MEMORY_BYTES`) and whose CPU time is capped
(``RLIMIT_CPU``), and the parent kills it at :data:`SECONDS` of wall time. Whatever goes wrong in there comes
back as one line naming the work (exit 2 at the command line), never as a hang or a crash of the caller.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

SECONDS = 60.0
"""Wall-time limit of the supplied sections' rendering: the packaged report's whole body renders in ~1 s here."""
MEMORY_BYTES = 1 << 30
"""Address space the child may add to what it inherits (1 GiB): the largest packaged section (the decision
gallery, images inline) is a few MB of text."""


class BoundedRenderError(ValueError):
    """The child rendering supplied templates ran out of time or memory, or died; the message names the work."""


def _vm_bytes() -> int | None:
    """This process's virtual size (``VmSize`` of ``/proc/self/status``), None where it cannot be read."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _limit(memory: int, seconds: float) -> None:
    import resource

    vm = _vm_bytes()
    if vm is not None:
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        soft = vm + memory
        resource.setrlimit(resource.RLIMIT_AS, (soft if hard == resource.RLIM_INFINITY else min(soft, hard), hard))
    used = os.times()
    cpu = int(used.user + used.system + seconds) + 1
    _, hard = resource.getrlimit(resource.RLIMIT_CPU)
    resource.setrlimit(resource.RLIMIT_CPU, (cpu if hard == resource.RLIM_INFINITY else min(cpu, hard), hard))


def _child(work: Callable[[], Any], conn: Any, memory: int, seconds: float) -> None:
    try:
        _limit(memory, seconds)
        conn.send(("ok", work()))
    except MemoryError:
        conn.send(("error", "it needs more than the memory limit"))
    except RecursionError:
        conn.send(("error", "it recurses without end (a template including itself?)"))
    except BaseException as exc:  # noqa: BLE001 - everything is reported to the parent as one line
        try:
            conn.send(("raise", exc))
        except Exception:  # an exception that does not pickle
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        conn.close()


def run_bounded(work: Callable[[], Any], *, what: str, seconds: float = SECONDS,
                memory_bytes: int = MEMORY_BYTES, start: str = "fork") -> Any:
    """``work()`` run in a child under the limits; its result (picklable), or the exception it raised (re-raised
    here), or :class:`BoundedRenderError` naming ``what`` when it ran out of time or memory or died. ``start``:
    ``fork`` (fast; ``work`` may be any callable) or ``spawn`` (a fresh interpreter, ``work`` picklable: for work
    that runs thread pools, which a fork of a process already running them can deadlock)."""
    import multiprocessing

    ctx = multiprocessing.get_context(start)
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(work, send, memory_bytes, seconds), daemon=True)
    child.start()
    send.close()
    try:
        if not recv.poll(seconds):
            raise BoundedRenderError(f"{what}: refused: it did not finish within {seconds:g} s (a loop without "
                                     "end?)")
        try:
            kind, value = recv.recv()
        except (EOFError, OSError):
            raise BoundedRenderError(f"{what}: refused: it was stopped (the limits of {seconds:g} s "
                                     f"CPU time and {memory_bytes >> 20} MiB of memory)") from None
    finally:
        recv.close()
        if child.is_alive():
            child.join(1.0)
        if child.is_alive():
            child.kill()
        child.join()
    if kind == "ok":
        return value
    if kind == "raise":
        raise value
    raise BoundedRenderError(f"{what}: refused: {value}")


__all__ = ["MEMORY_BYTES", "SECONDS", "BoundedRenderError", "run_bounded"]
