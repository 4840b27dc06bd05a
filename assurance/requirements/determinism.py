"""EL-R11's campaign checks: the results table recomputes identically, and re-run shards give the same readouts.

Timings are the only readouts allowed to differ between two runs of one campaign (``TIMING_COLUMNS``,
docs/architecture.md 4.2).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from assurance.analysis.metrics import ScenarioMetrics, rows_to_frame
from assurance.analysis.table import image_readouts, results_table
from assurance.bounded import BoundedRenderError, run_bounded
from assurance.campaign import readouts
from assurance.campaign.manifest import data_sha256
from assurance.campaign.run import CampaignConfig, execute, monitor_models, plan
from assurance.dataio.layouts import data_source
from assurance.perturbations import TRAITS
from assurance.requirements.records import FAIL, INSUFFICIENT, PASS, Evidence
from assurance.system.model import load_model_spec
from el.classes.labels import UAVID, LabelSet
from el.geometry.config import CoreConfig
from el.segmentation.contract import weights_sha256_of
from el.segmentation.factory import load_model
from el.segmentation.onnx_engine import file_identity

MAX_THREADS = 256
"""The most threads per worker a run may record: the re-run starts that many (a manifest's count is the applicant's)."""
RERUN_SECONDS = 900.0
"""Wall and CPU seconds one re-run shard may take: a release shard takes seconds; a network that loops without end
is stopped, the re-run's evidence insufficient."""
RERUN_MEMORY = 16 << 30
"""Address space one re-run shard may add to what the process holds (16 GiB)."""

TIMING_COLUMNS: frozenset[str] = frozenset({
    "read_s", "perturb_s", "segmentation_s", "candidates_s", "monitoring_s", "total_s", "overhead_s", "seconds",
    "overhead_s_lo95", "overhead_s_hi95",
})
"""Readout and table columns that may differ between two runs of the same campaign (docs/architecture.md 4.2)."""
_RERUN = "re-run of campaign shards"


def check_table_recomputation(run: str | Path, *, n_boot: int = 500) -> Evidence:
    """EL-R11: the results table recomputed from the readouts is the same whatever the order in which
    the shards are read, and equals the run's stored ``results.csv`` (if any), timing columns aside."""
    import pandas as pd

    run = Path(run)
    name = "results table recomputed from the readouts"
    table = results_table(run, n_boot=n_boot)
    images = readouts.load_table(run, "images")
    cands = readouts.load_table(run, "candidates")
    rng = np.random.default_rng(12345)
    shuffled = image_readouts(images.iloc[rng.permutation(len(images))],
                              cands.iloc[rng.permutation(len(cands))] if len(cands) else cands)
    rows = []
    for r in table.itertuples(index=False):
        sm = ScenarioMetrics(r.perturbation, int(r.severity), r.monitor, n_boot=n_boot, seed=0)
        sm.extend(shuffled.get((r.perturbation, int(r.severity), r.monitor), []))
        rows.append(sm.compute())
    again = rows_to_frame(rows)
    cols = [c for c in again.columns if c not in TIMING_COLUMNS]
    problems = []
    if not table[cols].reset_index(drop=True).equals(again[cols]):
        diff = [c for c in cols if not table[c].reset_index(drop=True).equals(again[c])]
        problems.append({"what": "shuffled readouts", "columns": ", ".join(diff)})
    stored = run / "results.csv"
    if stored.is_file():
        full = results_table(run)  # the stored table used the default resamples
        old = pd.read_csv(stored)
        num = [c for c in cols if c in old.columns and c not in ("perturbation", "monitor")]
        if len(old) != len(full) or list(old["monitor"]) != list(full["monitor"]):
            problems.append({"what": "results.csv", "columns": "rows differ"})
        else:
            a, b = old[num].to_numpy(float), full[num].to_numpy(float)
            close = np.isclose(a, b, rtol=1e-5, atol=1e-9, equal_nan=True)  # CSV keeps 6 significant digits
            if not close.all():
                bad = sorted({num[j] for j in np.flatnonzero(~close.all(axis=0))})
                problems.append({"what": "results.csv", "columns": ", ".join(bad)})
    if problems:
        return Evidence(name, FAIL, "the results table is not reproducible from the readouts",
                        tuple(problems), ("what", "columns"))
    extra = " and equals results.csv" if stored.is_file() else " (no results.csv stored to compare with)"
    return Evidence(name, PASS, f"{len(table)} rows identical whatever the shard order{extra}")


def _campaign_config(man: Mapping[str, Any]) -> Any:
    """The CampaignConfig a run's manifest records."""
    cfg_d = dict(man["config"])
    cfg_d["core"] = CoreConfig.from_dict(cfg_d["core"])
    for k in ("perturbations", "severities", "monitors"):
        cfg_d[k] = tuple(cfg_d[k])
    return CampaignConfig(**cfg_d)


def _run_labels(source: Any) -> Any:
    """The label set of a run's network: a system file's model records it; the shipped network and a weights file
    of the project's own architecture segment into UAVid's classes."""
    if isinstance(source, Mapping) and source.get("labels"):
        return LabelSet.from_dict(source["labels"])
    return UAVID


def _replan(man: Mapping[str, Any], config: Any, own_model: bool) -> list[Any] | str:
    """The run's tasks planned again on its data folder, or why they cannot be (data or weights gone or changed)."""
    data = data_source(man["data"])  # the run's [data] table when it had one
    if not Path(data).is_dir():
        return f"insufficient evidence: the run's data folder {data} is gone"
    weights = (man.get("weights") or {}).get("path")
    named = (man.get("weights") or {}).get("model")
    source = getattr(config, "weights", None)
    if not own_model and isinstance(source, Mapping):  # a system file's model: it must load as it did
        try:
            now = weights_sha256_of(load_model_spec(source))
        except Exception as exc:
            return f"insufficient evidence: the run's model cannot be loaded now: {exc}"
        if now != man["weights"].get("sha256"):
            return "insufficient evidence: the run's model reports other weights than in the run"
    elif not own_model and named:  # a model registered by name: it must still load and report the same weights
        try:
            now = weights_sha256_of(load_model(named))
        except Exception as exc:
            return f"insufficient evidence: the run's model {named!r} cannot be loaded now: {exc}"
        if now != man["weights"].get("sha256"):
            return f"insufficient evidence: the model {named!r} reports other weights than in the run"
    elif not own_model:
        if not weights or not Path(weights).is_file():
            return f"insufficient evidence: the run's weights {weights} are gone"
        try:
            now_sha = file_identity(weights)  # an ONNX file's external data included
        except Exception as exc:
            return f"insufficient evidence: the run's weights {weights} cannot be read now: {exc}"
        if now_sha != man["weights"].get("sha256"):
            return f"insufficient evidence: the weights file {weights} changed since the run"

    try:
        models = monitor_models(config.monitors, _run_labels(source))
    except Exception as exc:  # e.g. a learned monitor's model file is gone or altered
        return f"insufficient evidence: the run's monitors cannot be built now: {exc}"
    if models != (man.get("monitor_models") or {}):
        return (f"insufficient evidence: the monitors' fitted models changed since the run (recorded "
                f"{man.get('monitor_models') or 'none'}, now {models})")
    try:
        planned = plan(data, config)
        data_sha = data_sha256(data, planned)
    except Exception as exc:  # the data folder no longer reads as the campaign's data set
        return f"insufficient evidence: cannot re-plan the run on {data}: {exc}"
    if data_sha != man["data"]["sha256"]:
        return f"insufficient evidence: the data in {data} changed since the run"
    return planned


def _differing_columns(stored: Any, again: Any) -> list[str]:
    """The readout columns (timings aside) in which a re-run shard's table differs from the stored one.

    Columns the code added since the run (in ``readouts.COLUMNS`` but not in the stored table, e.g. the
    image width and height) are left out, so a run recorded before them can still be re-run.
    """
    added = [c for c in again.columns if c not in stored.columns and c in set().union(*readouts.COLUMNS.values())]
    again = again.drop(columns=added)
    if list(stored.columns) != list(again.columns):
        return ["(the columns differ)"]
    if len(stored) != len(again):
        return [f"(rows: {len(stored)} stored, {len(again)} re-run)"]
    diff = []
    for c in stored.columns:
        if c in TIMING_COLUMNS or c == "traceback":
            continue
        x, y = stored[c].to_numpy(), again[c].to_numpy()
        same = np.array_equal(x, y, equal_nan=True) if x.dtype.kind == "f" else (x == y).all()
        if not same:
            diff.append(c)
    return diff


def check_rerun(run: str | Path, *, shards: int = 1, work_dir: str | Path, threads: int | None = None,
                segmenter: Any = None) -> Evidence:
    """EL-R11: re-run ``shards`` tasks of a campaign from scratch and compare their readouts with the stored
    ones (timings aside). Insufficient when the data or weights are gone or changed since the run.

    The tasks re-run are the first ones (sorted shard names) of a perturbation that draws random numbers,
    so the per-image seeding is exercised too. ``segmenter`` replaces the model of the manifest's weights.
    """
    run = Path(run)
    man = readouts.read_manifest(run)
    config = _campaign_config(man)
    planned = _replan(man, config, own_model=segmenter is not None)
    if isinstance(planned, str):
        return Evidence(_RERUN, INSUFFICIENT, planned)
    tasks = {t.shard_name: t for t in planned}
    done = sorted(n for n in tasks if readouts.shard_done(run, n))
    if not done:
        return Evidence(_RERUN, INSUFFICIENT, "insufficient evidence: no finished shard to re-run")
    randomised = [n for n in done if TRAITS[tasks[n].perturbation].random]
    pick = (randomised or done)[:max(1, shards)]
    work = Path(work_dir)
    (work / readouts.SHARDS).mkdir(parents=True, exist_ok=True)
    rows = []
    recorded = man.get("threads_per_worker")
    if recorded is not None and not (isinstance(recorded, int) and 1 <= recorded <= MAX_THREADS):
        return Evidence(_RERUN, INSUFFICIENT, f"insufficient evidence: the run records {recorded!r} threads per "
                        f"worker: not a count from 1 to {MAX_THREADS}")
    threads = threads or recorded or os.cpu_count() or 1
    max_rows = readouts.table_caps(man)[0]  # each table read bounded (a re-sealed shard of 100 M rows)
    for shard in pick:  # the campaign's own thread count: float sums depend on it
        try:  # the applicant's network runs here: in a child with a time and a memory limit, never a hang
            run_bounded(partial(execute, tasks[shard], config, str(work), threads, segmenter),
                        what=f"the re-run of shard {shard}", seconds=RERUN_SECONDS, memory_bytes=RERUN_MEMORY,
                        start="spawn")  # a fork of a process that ran torch or ONNX Runtime threads can deadlock
        except BoundedRenderError as exc:
            return Evidence(_RERUN, INSUFFICIENT, f"insufficient evidence: {exc}")
        for table in readouts.TABLES:
            a = readouts.read_table_file(run / readouts.SHARDS / shard / f"{table}.parquet", max_rows=max_rows,
                                         within=run)
            b = readouts.read_table_file(work / readouts.SHARDS / shard / f"{table}.parquet", max_rows=max_rows)
            diff = _differing_columns(a, b)
            rows.append({"shard": shard, "table": table, "rows": len(a), "differing_columns": ", ".join(diff) or "-"})
    cols = ("shard", "table", "rows", "differing_columns")
    if any(r["differing_columns"] != "-" for r in rows):
        return Evidence(_RERUN, FAIL, f"re-running {len(pick)} shard(s) changed the readouts", tuple(rows), cols)
    return Evidence(_RERUN, PASS, f"re-running {len(pick)} shard(s) gave identical readouts (timings aside)",
                    tuple(rows), cols)
