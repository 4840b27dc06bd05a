"""What the evidence report assessed (versions, hashes of code, weights, data, configuration, registry), and what
changed since a baseline run."""

from __future__ import annotations

import math
import platform
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from assurance import __version__
from assurance import requirements as rq
from assurance.analysis.table import results_table
from assurance.campaign import readouts
from assurance.campaign.integrity import tree_sha256
from assurance.code_identity import code_identity
from assurance.evidence.navigation import anchor, short_name
from assurance.evidence.text import STATE_CLASS, fmt, to_float
from el.base.errors import WeightsError
from el.base.hashing import sha256_file
from el.segmentation.onnx_engine import file_identity

HIGHER_IS_BETTER = {"g_cm": True, "g_rm": True, "g_star": True, "mcc": True, "f1": True, "precision": True,
                    "recall": True, "fp_rate": False, "overhead_s": False, "unsafe_landing_rate": False,
                    "unsafe_landing_ub95": False}




def _file_identity(path: str) -> str | None:
    """A weights file's identity now: an ONNX file's external data included (None: it cannot be read)."""
    try:
        return file_identity(path)
    except WeightsError:
        return None


def _targets_text(registry: rq.Registry, origins: Mapping[str, str] | None) -> str:
    """The parameters the system sets, each with where the file sets it, and the source of them all."""
    if not registry.targets:
        return "the registry's parameters (no override)"
    return (", ".join(f"{k} = {v}" + (f" ({origins[k]})" if origins and k in origins else "")
                      for k, v in registry.targets.items()) + f" (from {registry.targets_source})")


def identity(inp: Any, *, templates: Path, origins: Mapping[str, str] | None = None) -> tuple[list[dict], dict]:
    """What was assessed: (the report's identity rows, the same facts for evidence.json), from what the report read
    (``inp``: ``assurance.evidence.context.Inputs``: the run, its manifest and check, the registry, the requirement
    results, the results table); ``templates``: the report's template folder, hashed; ``origins``: where the system
    file sets each of its requirement parameters (``assurance.system.build.target_origins``)."""
    run, man, registry, check = inp.run, inp.manifest, inp.registry, inp.check
    req_path, req_doc, csv_path = inp.req_path, inp.req_doc, inp.csv_path
    weights = man.get("weights") or {}
    wpath = weights.get("path")
    current = ""
    if wpath and Path(wpath).is_file():
        current = "matches the file now" if _file_identity(wpath) == weights.get("sha256") else \
            "differs from the file now (it changed since the run)"
    elif wpath:
        current = "file no longer present"
    code = man.get("code") or {}
    now = code_identity()
    code_sha, n_files = now["sha256"], now["files"]
    tpl_sha, n_tpl = tree_sha256([templates], base=templates.parent)
    data = man.get("data") or {}
    versions = man.get("versions") or {}
    cfg_sha = rq.config_sha256(man.get("config") or {})
    now_commit = now["git_commit"]
    rows = [
        {"item": "Toolkit", "value": f"uav-el-assurance {code.get('version', '?')} (campaign); "
                                     f"{__version__} (this report)", "sha256": "", "note": ""},
        {"item": "Code (git)", "value": f"campaign: {code.get('git_commit') or _no_commit(code)}",
         "sha256": "", "note": f"report: {now_commit or _no_commit(now)}"},
        {"item": "Code (package files)", "value": f"{n_files} files of el/, assurance/ and evidence_templates/ as "
                                                  f"{now['source']} at report time", "sha256": code_sha,
         "note": f"campaign: {code['sha256'] if code.get('sha256') else 'not recorded'}; a '-dirty' commit means "
                 "uncommitted changes: rely on this hash"},
        {"item": "System file", "value": _system_text(man), "sha256": (man.get("system") or {}).get("sha256") or "",
         "note": "every value it sets: section 'The system assessed'"},
        {"item": "Weights", "value": str(wpath or weights.get("model") or "not recorded"),
         "sha256": weights.get("sha256") or "",
         "note": current},
        {"item": "Data", "value": f"{data.get('path', '?')} ({data.get('images', '?')} images)",
         "sha256": data.get("sha256") or "", "note": "hash of every image and label file (relative path and SHA-256)"},
        {"item": "Configuration", "value": "campaign configuration (manifest.json 'config', canonical JSON)",
         "sha256": cfg_sha, "note": ""},
        {"item": "Requirement registry", "value": str(registry.path), "sha256": registry.sha256, "note": ""},
        {"item": "Requirement targets", "value": _targets_text(registry, origins),
         "sha256": registry.parameters_sha256,
         "note": "hash of the effective parameters (canonical JSON); the requirement results must carry it"},
        {"item": "Requirement test results", "value": str(req_path) if req_path else "not given",
         "sha256": sha256_file(req_path) if req_path else "",
         "note": (f"pytest session finished {req_doc.get('context', {}).get('finished', '?')}" if req_doc else "")},
        {"item": "Results table", "value": str(csv_path), "sha256": sha256_file(csv_path), "note": ""},
        {"item": "Report templates", "value": f"{templates} ({n_tpl} files)", "sha256": tpl_sha, "note": ""},
        {"item": "Run folder", "value": str(run), "sha256": sha256_file(run / "manifest.json"),
         "note": "hash of manifest.json"},
        {"item": "Run readouts", "value": f"{check.shards} shard(s)" + (" (written before shard hashes: not "
                                                                         "verifiable)" if check.legacy else
                                                                         ", each verified against its SHA-256"),
         "sha256": check.digest, "note": "run digest: the shards' hashes in task order; the requirement "
                                         "results must carry it"},
        {"item": "Software", "value": (f"Python {versions.get('python', '?')}, torch {versions.get('torch', '?')}, "
                                       f"numpy {versions.get('numpy', '?')}"),
         "sha256": "", "note": f"campaign machine: {versions.get('platform', '?')}"},
        {"item": "Report machine", "value": f"Python {sys.version.split()[0]} on {platform.platform()}",
         "sha256": "", "note": ""},
    ]
    ident = {"toolkit_version": __version__, "campaign_version": code.get("version"),
             "git_commit_campaign": code.get("git_commit"), "git_commit_report": now_commit,
             "code_sha256": code_sha, "weights_path": wpath, "weights_sha256": weights.get("sha256"),
             "data_path": data.get("path"), "data_sha256": data.get("sha256"), "config_sha256": cfg_sha,
             "registry_path": str(registry.path), "registry_sha256": registry.sha256,
             "targets": dict(registry.targets), "targets_source": registry.targets_source,
             "parameters_sha256": registry.parameters_sha256,
             "requirements_results_path": str(req_path) if req_path else None,
             "requirements_results_sha256": sha256_file(req_path) if req_path else None,
             "results_csv_sha256": sha256_file(csv_path), "templates_sha256": tpl_sha,
             "manifest_sha256": sha256_file(run / "manifest.json"), "run_digest": check.digest,
             "run_shards_verified": not check.legacy, "versions": dict(versions),
             "system_sha256": (man.get("system") or {}).get("sha256"),
             "system_path": (man.get("system") or {}).get("path")}
    return rows, ident


def _no_commit(code: Mapping[str, Any]) -> str:
    return "none (installed package: identified by version and file hash)" if code.get("source") == "installed" \
        else "unknown"


def _system_text(man: Mapping[str, Any]) -> str:
    rec = man.get("system")
    if not rec:
        return "not recorded (a run made before system files)"
    where = "the embedded default (the shipped system)" if rec.get("default") else rec.get("path")
    return f"{rec.get('name')}: {where}"


def baseline_view(baseline: Path, man: Mapping[str, Any], ident: Mapping[str, Any], table: Any,
                  results: Mapping[str, rq.RequirementResult], registry: rq.Registry,
                  baseline_requirements: Path | None, n_boot: int) -> dict[str, Any]:
    """What changed since a baseline run: identity, figures per scenario and requirement states."""
    bman = readouts.read_manifest(baseline)
    btable = results_table(baseline, n_boot=n_boot)
    bw, bd, bc = (bman.get("weights") or {}), (bman.get("data") or {}), (bman.get("code") or {})
    pairs = [
        ("Weights SHA-256", bw.get("sha256"), ident["weights_sha256"]),
        ("Data SHA-256", bd.get("sha256"), ident["data_sha256"]),
        ("Configuration SHA-256", rq.config_sha256(bman.get("config") or {}), ident["config_sha256"]),
        ("Git commit", bc.get("git_commit"), ident["git_commit_campaign"]),
        ("Toolkit version", bc.get("version"), ident["campaign_version"]),
        ("torch", (bman.get("versions") or {}).get("torch"), (ident.get("versions") or {}).get("torch")),
    ]
    identity = [{"item": k, "baseline": str(a), "current": str(b), "changed": "changed" if a != b else "same"}
                for k, a, b in pairs]
    keys = ["perturbation", "severity", "monitor"]
    order = {k: i for i, k in enumerate(zip(*(table[c] for c in keys), strict=True))}
    order.update({k: len(order) + i for i, k in enumerate(zip(*(btable[c] for c in keys), strict=True))
                  if k not in order})
    merged = table.merge(btable, on=keys, how="outer", suffixes=("", "_base"), indicator=True)
    merged = merged.iloc[np.argsort([order[k] for k in zip(*(merged[c] for c in keys), strict=True)], kind="stable")]
    figs = ("g_star", "g_rm", "mcc", "recall", "fp_rate", "unsafe_landing_rate", "unsafe_landing_ub95", "overhead_s")
    rows = []
    for rec in merged.to_dict("records"):
        status = {"both": "", "left_only": "new", "right_only": "removed"}[str(rec["_merge"])]
        cells = []
        for f in figs:
            a, b = to_float(rec.get(f"{f}_base")), to_float(rec.get(f))
            d = b - a
            cls = ""
            if math.isfinite(d) and abs(d) > 1e-12:
                better = (d > 0) == HIGHER_IS_BETTER[f]
                cls = "better" if better else "worse"
            cells.append({"base": fmt(a), "now": fmt(b), "delta": (f"{d:+.3f}" if math.isfinite(d) else ""),
                          "cls": cls})
        rows.append({"scenario": f"{rec['perturbation']} (s{int(rec['severity'])})", "monitor": rec["monitor"],
                     "status": status, "cells": cells})
    req_changes: list[dict[str, Any]] = []
    req_note = ""
    by_requirement: dict[str, dict[str, Any]] = {}
    if baseline_requirements is not None:
        bres, _ = rq.load_results(baseline_requirements, registry)
        for rid, res in results.items():
            old = bres[rid].state
            tests = changed_tests(bres[rid], res)
            by_requirement[rid] = {"baseline": old, "changed": old != res.state, "tests": tests}
            if old != res.state or tests:
                req_changes.append({"id": rid, "title": res.title, "baseline": old, "current": res.state,
                                    "baseline_class": STATE_CLASS[old], "current_class": STATE_CLASS[res.state],
                                    "tests": tests})
        req_changes.sort(key=lambda r: r["baseline"] == r["current"])  # state changes first
        moved = sum(r["baseline"] != r["current"] for r in req_changes)
        req_note = (f"{moved} requirement state(s) changed since the baseline, {len(req_changes) - moved} more "
                    f"requirement(s) with a test added, removed or of another outcome ({baseline_requirements})."
                    if req_changes else
                    f"No requirement changed state or test outcome since the baseline ({baseline_requirements}).")
    else:
        req_note = ("The baseline's requirement results were not given (--baseline-requirements): "
                    "state changes cannot be shown.")
    return {"run": str(baseline), "identity": identity, "figures": [f.replace("_", " ") for f in figs],
            "rows": rows, "requirements": req_changes, "requirements_note": req_note, "by_requirement": by_requirement}


def changed_tests(before: rq.RequirementResult, now: rq.RequirementResult) -> list[dict[str, str]]:
    """The claiming tests of a requirement whose outcome differs from the baseline's (added and removed ones too),
    each with its anchor in the report's test list (none for a removed test)."""
    old = {t.nodeid: t.outcome for t in before.tests}
    new = {t.nodeid: t.outcome for t in now.tests}
    return [{"name": short_name(n), "anchor": anchor("test", n) if n in new else "",
             "baseline": old.get(n, "absent"), "current": new.get(n, "absent")}
            for n in dict.fromkeys([*new, *old]) if old.get(n) != new.get(n)]
