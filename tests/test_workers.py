"""Worker processes tied to the campaign's process: the dask backend's workers get the kernel's guard too."""

from __future__ import annotations

import logging
import os
import signal
import sys

import pytest

from assurance.workers import dask_logging_follows_ours, dask_map, dask_parent_pid

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")


def test_only_a_local_clusters_children_are_told_to_die_with_this_process():
    dask = pytest.importorskip("dask")
    assert dask_parent_pid(None) == os.getpid()
    assert dask_parent_pid("tcp://127.0.0.1:8786") is None  # a running scheduler's workers are not ours to end
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        assert dask_parent_pid(None) is None  # the fork server's children: guarding them would end them at once


@linux_only
def test_a_local_dask_cluster_s_workers_get_the_parent_death_signal():
    pytest.importorskip("dask.distributed")

    def probe(item: int, parent_pid: int | None) -> tuple[int, int, int]:
        import ctypes

        from assurance.workers import die_with_parent

        die_with_parent(parent_pid)
        sig = ctypes.c_int(0)
        ctypes.CDLL(None).prctl(2, ctypes.byref(sig), 0, 0, 0)  # PR_GET_PDEATHSIG
        return item, os.getppid(), sig.value

    out = sorted(dask_map(probe, [0, 1, 2], jobs=2, scheduler=None))
    assert [o[0] for o in out] == [0, 1, 2]
    assert {(ppid, sig) for _, ppid, sig in out} == {(os.getpid(), int(signal.SIGKILL))}


@pytest.mark.slow
@linux_only
def test_dask_workers_die_with_a_sigkilled_campaign(tmp_path):
    pytest.importorskip("dask.distributed")
    from assurance.cli import main
    from assurance.fault_injection.bounds import killed_campaign_survivors
    from assurance.fault_injection.table import build_workspace

    ws = build_workspace(tmp_path, main=main)
    assert killed_campaign_survivors(ws, ws / "killed", backend="dask") == []


def test_dask_s_log_lines_follow_the_toolkit_s_level_unless_the_user_set_theirs(monkeypatch):
    """WARNING by default (no INFO line per worker and comm), INFO at -v; DASK_LOGGING__DISTRIBUTED wins."""
    pytest.importorskip("distributed")
    root, dist = logging.getLogger(), logging.getLogger("distributed")
    levels = root.level, dist.level
    monkeypatch.delenv("DASK_LOGGING__DISTRIBUTED", raising=False)
    try:
        root.setLevel(logging.WARNING)
        dask_logging_follows_ours()
        assert os.environ["DASK_LOGGING__DISTRIBUTED"] == "warning" and dist.level == logging.WARNING
        del os.environ["DASK_LOGGING__DISTRIBUTED"]
        root.setLevel(logging.INFO)
        dask_logging_follows_ours()
        assert dist.level == logging.INFO
        os.environ["DASK_LOGGING__DISTRIBUTED"] = "error"
        dask_logging_follows_ours()
        assert dist.level == logging.ERROR
    finally:
        os.environ.pop("DASK_LOGGING__DISTRIBUTED", None)
        root.setLevel(levels[0])
        dist.setLevel(levels[1])
