"""Evaluation campaigns (docs/architecture.md 4.2): perturbation x image tasks, every monitor configuration per task.

One task = one (perturbation, severity, image) through the flight kernel (``assurance.campaign.task``): the
frame perturbed (seeded per image), segmented and its candidates found **once**, every candidate judged with
every monitor configuration in one pass, sharing work between them (``judging``: each HD patch segmented once for
every tau, MC-dropout samples drawn once per rho), each configuration charged the monitoring time it would have
spent alone, and each configuration's decision concluded by the kernel.

Results go to a readouts store (``assurance.campaign.readouts``): one shard per task, written atomically, so
an interrupted campaign resumes where it stopped, and a bad image is a recorded fault, not a crash.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from assurance.attest.keys import load_signing_key
from assurance.campaign import frame_cache, readouts
from assurance.campaign.attestation import sign_run
from assurance.campaign.clearance import sample_clearance_m
from assurance.campaign.faults import config_faults
from assurance.campaign.label_pin import check_resumed_labels, flown_labels
from assurance.campaign.manifest import (  # noqa: F401  (re-exported)
    check_monitor_networks,
    manifest,
    monitor_models,
)
from assurance.campaign.task import (  # noqa: F401  (re-exported)
    CampaignConfig,
    Task,
    run_task,
    task_parts,
    task_seed,
)
from assurance.dataio.layouts import iter_samples
from assurance.progress import progress as bar
from assurance.system import default_system
from assurance.system.model import load_model_spec
from assurance.workers import bounded_jobs, dask_map, die_with_parent

# ------------------------------------------------------------------------------------------------
# The runner
# ------------------------------------------------------------------------------------------------
_WORKER_STATE: dict[str, Any] = {}


def campaign_network(weights: str | dict[str, Any] | None, threads: int, working_width: int | None = None) -> Any:
    """The campaign's network in this process, loaded once and kept (a worker's, or the sequential run's, whose
    checks and tasks share it), at the campaign's working width and ``threads`` (:func:`network_threads`)."""
    key = f"{weights}|{threads}|{working_width}"
    if _WORKER_STATE.get("key") != key:
        _WORKER_STATE["segmenter"] = load_model_spec(weights, threads=threads, working_width=working_width)
        _WORKER_STATE["key"] = key
    return _WORKER_STATE["segmenter"]


def network_threads(jobs: int) -> int:
    """The threads each of ``jobs`` workers gives its network: the cores shared out."""
    return max(1, (os.cpu_count() or 1) // max(1, jobs))


def execute(task: Task, config: CampaignConfig, run_dir: str, threads: int, segmenter: Any = None,
            expected_models: dict[str, str] | None = None, parent_pid: int | None = None) -> dict[str, Any]:
    """Worker entry point: run one task and write its shard; returns a small summary. ``parent_pid``: the
    campaign's process, in a loky worker: the worker dies with it (``workers.die_with_parent``)."""
    die_with_parent(parent_pid)
    if segmenter is None:
        segmenter = campaign_network(config.weights, threads, config.core.working_width)
    t = time.perf_counter()
    rows = run_task(task, config, segmenter, world_clearance=sample_clearance_m, expected_models=expected_models)
    hashes = readouts.write_shard(Path(run_dir), task.shard_name, rows)
    faults = [r["fault"] for r in rows["images"] if r.get("fault")]
    return {"shard": task.shard_name, "seconds": time.perf_counter() - t, "fault": faults[0] if faults else "",
            "hashes": hashes}


def plan(data: str | Path, config: CampaignConfig) -> list[Task]:
    """All tasks of a campaign, in a fixed order (scene-major: a scene's scenarios one after the other, so that a
    worker given them as one batch decodes the scene once, ``assurance.campaign.frame_cache``). A task's readouts do
    not depend on the order (its seed is its own, ``task_seed``)."""
    samples = list(iter_samples(data, require_labels=True, poses=config.poses != "nominal"))
    if config.images is not None:
        samples = samples[: config.images]
    return [Task(p, s, sample) for sample in samples for p, s in config.scenarios()]


@dataclass(frozen=True)
class Execution:
    """How a campaign's tasks are run (none of it changes a readout): ``jobs`` worker processes (bounded by the
    cores), the ``backend`` (``loky`` or ``dask`` with its ``scheduler``), a progress bar, and ``on_result`` called
    with each finished task's summary."""

    jobs: int = 1
    backend: str = "loky"
    scheduler: str | None = None
    progress: bool = True
    on_result: Callable[[dict[str, Any]], None] | None = None


def run_campaign(
    data: str | Path,
    run_dir: str | Path,
    config: CampaignConfig,
    *,
    execution: Execution = Execution(),
    segmenter: Any = None,
    records: Sequence[Any] = (),
    system: Any = None,
    signing_key: Any = None,
) -> dict[str, Any]:
    """Run (or resume) a campaign; returns a summary {tasks, done, skipped, faults, config_faults, missing, repaired,
    seconds} (``config_faults``: the faults that are not the data's, ``assurance.campaign.faults``).

    ``segmenter`` replaces the model loaded from ``config.weights`` (any object with
    ``predict_frame``, ``predict_patch`` and ``mc_dropout``; picklable for parallel backends).
    ``records`` (e.g. the calibration cards of the configurations): hash-checked records that, like the
    fitted monitors, must have been fitted on the campaign's network (``check_network``), checked before
    anything is written.

    Finished shards that verify are skipped, so re-running an interrupted campaign completes it; a
    shard that fails verification (altered, truncated, missing though recorded) is moved to
    ``RUN/damaged/`` and run again (``summary["repaired"]`` says which and why). The run's manifest
    must match the config (a different campaign in the same folder is an error). Nothing is
    written before the configuration, the data and the weights have been checked.

    Every invocation ends by signing the run as it stands (``RUN/campaign.dsse.json``,
    ``assurance.campaign.attestation``) with ``signing_key`` (an ``assurance.attest.keys.SigningKey``; None: the
    user's key, ``load_signing_key``, created on first use; False: not signed).
    """
    run_dir = Path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise readouts.RunError(f"{run_dir}: exists and is not a folder (--out names the run folder)")
    frame_cache.clear()  # this process's kept frame (a sequential run) is never one of an earlier campaign's
    tasks = plan(data, config)
    if not tasks:
        raise ValueError(f"{data}: no images to evaluate")
    run = execution
    jobs = run.jobs if run.backend == "dask" and run.scheduler else bounded_jobs(run.jobs)  # local: at most the cores
    threads = network_threads(jobs)
    # bad weights or an unknown model name are refused before the run folder exists; a sequential run's tasks use
    # this very network (and the command line's checks did)
    network = segmenter if segmenter is not None else campaign_network(config.weights, threads,
                                                                        config.core.working_width)
    signing_key = _signing_key(signing_key, run_dir)  # refused (no key, or one inside the run) before anything runs
    check_monitor_networks(config.monitors, network)
    for record in records:
        record.check_network(network)
    if system is None:
        system = default_system()
    man = manifest(data, config, tasks, threads=threads,
                   segmenter="weights" if segmenter is None else type(segmenter).__name__, model=network,
                   system=system.record(), labels=flown_labels(system, network))
    readouts.init_run(run_dir, man)
    check_resumed_labels(run_dir, man)  # a resumed run's shards were judged with its manifest's classes
    repaired = _set_aside_damaged(run_dir, tasks)
    todo = [t for t in tasks if not readouts.shard_done(run_dir, t.shard_name)]
    t0 = time.perf_counter()
    results: list[dict[str, Any]] = []
    for res in _dispatch(todo, config, run_dir, replace(run, jobs=jobs), threads=threads, segmenter=segmenter,
                         expected_models=man["monitor_models"]):
        results.append(res)
        if res.get("hashes"):
            readouts.record_shards(run_dir, {res["shard"]: res["hashes"]})
        if run.on_result:
            run.on_result(res)
    summary = _summary(run_dir, tasks, todo, results, repaired, time.perf_counter() - t0)
    readouts.append_log(run_dir, summary)
    if signing_key:
        summary["attestation"] = str(sign_run(run_dir, signing_key, summary))
    return summary


def _summary(run_dir: Path, tasks: Sequence[Task], todo: Sequence[Task], results: Sequence[dict[str, Any]],
             repaired: list[str], seconds: float) -> dict[str, Any]:
    """What a campaign invocation did (``run_campaign``'s return value, a line of ``RUN/log.jsonl``)."""
    faults = [f"{r['shard']}: {r['fault']}" for r in results if r["fault"]]
    return {"tasks": len(tasks), "done": len(results), "skipped": len(tasks) - len(todo), "faults": faults,
            "missing": [t.shard_name for t in todo if not readouts.shard_done(run_dir, t.shard_name)],
            "config_faults": config_faults(faults), "repaired": repaired, "seconds": seconds}


def _signing_key(given: Any, run_dir: Path) -> Any:
    """The key that signs the run: ``given``, or the user's (created on first use); False: none."""
    if given is not None:
        return given
    return load_signing_key(outside=run_dir)


def _set_aside_damaged(run_dir: Path, tasks: Sequence[Task]) -> list[str]:
    """Move the shards that fail verification to ``RUN/damaged/`` (kept for inspection) so they are run
    again; record the verified shards the index lacks. Returns one line per damaged shard."""
    if not readouts.has_integrity(run_dir):
        return []
    out = [line for line in [readouts.set_aside_index(run_dir)] if line]  # unreadable: rebuilt below
    index = readouts.read_index(run_dir)
    found: dict[str, dict[str, str] | None] = {}
    for t in tasks:
        name = t.shard_name
        folder = run_dir / readouts.SHARDS / name
        if not folder.exists():
            if name in index:
                out.append(f"{name}: shard folder missing")
                found[name] = None
            continue
        why = readouts.check_shard(run_dir, name, index.get(name))
        if why is None:
            if name not in index:
                found[name] = readouts.read_sums(folder)
            continue
        out.append(f"{name}: {why}")
        found[name] = None
        aside = run_dir / "damaged"
        aside.mkdir(exist_ok=True)
        k = 0
        while (aside / f"{name}.{k}").exists():
            k += 1
        folder.rename(aside / f"{name}.{k}")
    if found:
        readouts.record_shards(run_dir, found)
    return out


def _dispatch(todo: list[Task], config: CampaignConfig, run_dir: Path, run: Execution, *, threads: int,
              segmenter: Any, expected_models: dict[str, str] | None = None) -> Iterator[dict[str, Any]]:
    jobs, backend, scheduler, progress = run.jobs, run.backend, run.scheduler, run.progress
    if not todo:
        return
    if backend == "dask":
        gen = dask_map(execute, todo, jobs=jobs, scheduler=scheduler, config=config, run_dir=str(run_dir),
                       threads=threads, segmenter=segmenter, expected_models=expected_models)
        yield from bar(gen, total=len(todo), desc="campaign", enabled=progress)
        return
    if backend != "loky":
        raise ValueError(f"unknown backend {backend!r}; valid: loky, dask")
    if jobs <= 1:
        yield from bar((execute(t, config, str(run_dir), threads, segmenter, expected_models) for t in todo),
                       total=len(todo),
                       desc="campaign", enabled=progress)
        return
    from joblib import Parallel, delayed

    par = Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered",  # workers die with this process
                   initializer=die_with_parent, initargs=(os.getpid(),),
                   batch_size=len(config.scenarios()))  # a scene's scenarios to one worker: decoded once
    gen = par(delayed(execute)(t, config, str(run_dir), threads, segmenter, expected_models, os.getpid())
              for t in todo)
    with warnings.catch_warnings():
        # loky replaces a worker whose resident memory grew by 300 MB (its leak guard); MC-dropout
        # batches grow the allocator's arenas that much once. The task is not lost (the replacement
        # runs it and every shard is checked at the end), so the warning would only alarm.
        warnings.filterwarnings("ignore", message="A worker stopped while some jobs were given",
                                category=UserWarning)
        yield from bar(gen, total=len(todo), desc="campaign", enabled=progress)


def describe(summary: dict[str, Any]) -> str:
    """One paragraph for the terminal."""
    lines = [f"{summary['done']} task(s) run, {summary['skipped']} already done, of {summary['tasks']}"
             f" in {summary['seconds']:.1f} s"]
    if summary.get("repaired"):
        lines.append(f"{len(summary['repaired'])} damaged shard(s) failed verification and were run again "
                     "(the damaged copies are in RUN/damaged/):")
        lines += [f"  {r}" for r in summary["repaired"][:10]]
    if summary["faults"]:
        lines.append(f"{len(summary['faults'])} fault(s) recorded:")
        lines += [f"  {f}" for f in summary["faults"][:10]]
    if summary.get("missing"):
        lines.append(f"{len(summary['missing'])} task(s) left no shard (a worker died?); run the same command "
                     f"again to complete them: {', '.join(summary['missing'][:5])}")
    return "\n".join(lines)

