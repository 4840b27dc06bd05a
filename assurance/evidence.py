"""The evidence report (docs/architecture.md 4.7): what was assessed, against which requirements, with what result.

``generate(run, out, ...)`` reads a campaign run (manifest, readouts, results table), the requirement
registry and the requirement results of a test session (``pytest -m requirements --uav-el-run RUN``, JSON
written by ``assurance.pytest_plugin``), and writes into ``out``:

- ``evidence.html``: self-contained (CSS inline, images as data URIs), rendered from the Jinja2
  templates in ``assurance/templates/`` (autoescape on, undefined variables are errors);
- ``evidence.pdf``: the same HTML through WeasyPrint (skipped with a clear message if it is missing);
- ``evidence.json``: identity, requirement states, campaign checks and the results table, for tools;
- ``results.csv``: the results table the report shows; ``traceability.csv``: one row per (requirement,
  test) with outcome, state and artefact; ``SHA256SUMS``: the hashes of these files (and of
  ``junit.xml`` when the evidence step wrote one into ``out``);
- the PDF is PDF/A-3b with ``evidence.json``, ``results.csv``, ``traceability.csv``, ``junit.xml`` and
  ``SHA256SUMS`` attached (that copy of SHA256SUMS lists every file but the PDF itself).

Paths in the report and its JSON are relative to the project root when they lie under it.

Everything the templates show is computed here, as finished strings: the templates compute nothing.
The gate (``EvidenceReport.exit_code``): 1 when a requirement is failed (and not waived), when the
requirement results are not bound to this run, code and registry (the run digest, code hash and
registry hash their test session recorded), when a state contradicts its own tests or this report's
check of the run, or when a waiver has expired; with ``strict`` (which ignores waivers) also when a
requirement is not verified or the PDF could not be written; else 0. A run whose shards fail
verification gets no report (``readouts.DamagedRunError``, exit 4 at the command line).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import platform
import sys
import warnings
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from assurance import __version__, readouts
from assurance import requirements as rq
from assurance.integrity import RunCheck, code_sha256, tree_sha256, verify_run
from assurance.metrics import clopper_pearson_upper
from assurance.table import results_table, write_csv
from el.hashing import sha256_file

EVIDENCE_FORMAT = "uav-el-evidence/1"
ROOT = Path(__file__).resolve().parent.parent
TEMPLATES_DIR = Path(__file__).resolve().parent / "templates"  # package data: found by an installed wheel too
TEMPLATE = "report.html.j2"
PDF_HINT = ("install WeasyPrint (`pip install weasyprint`, or `pip install -e '.[pdf]'`) and the Pango "
            "library it needs (Debian/Ubuntu: `apt-get install libpango-1.0-0 libpangoft2-1.0-0`)")
STATE_CLASS = {rq.VERIFIED: "verified", rq.FAILED: "failed", rq.NOT_VERIFIED: "not-verified"}
STATUS_CLASS = {rq.PASS: "verified", rq.FAIL: "failed", rq.INSUFFICIENT: "not-verified"}
STATUS_TEXT = {rq.PASS: "pass", rq.FAIL: "fail", rq.INSUFFICIENT: "insufficient evidence"}
HIGHER_IS_BETTER = {"g_cm": True, "g_rm": True, "g_star": True, "mcc": True, "f1": True, "precision": True,
                    "recall": True, "fp_rate": False, "overhead_s": False, "unsafe_landing_rate": False,
                    "unsafe_landing_ub95": False}


@dataclass
class EvidenceReport:
    """What ``generate`` wrote and what the gate says."""

    out: Path
    html: Path
    json: Path
    pdf: Path | None
    pdf_error: str | None
    states: dict[str, str]
    exit_code: int
    warnings: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    waived: list[str] = field(default_factory=list)

    def ids(self, state: str) -> list[str]:
        return [rid for rid, s in self.states.items() if s == state]

    def summary_lines(self) -> list[str]:
        """One line per state (with the ids of the failed and not-verified ones) and where the report is."""
        lines = []
        for state in rq.STATES:
            ids = self.ids(state)
            shown = [f"{i} (waived)" if i in self.waived else i for i in ids]
            tail = f"  {', '.join(shown)}" if ids and state != rq.VERIFIED else ""
            lines.append(f"{state + ':':<14}{len(ids):3d}{tail}")
        lines += [f"gate problem: {p}" for p in self.problems]
        files = [self.html] + ([self.pdf] if self.pdf else []) + [self.json]
        lines.append("report: " + ", ".join(str(f) for f in files))
        if self.pdf_error:
            lines.append(self.pdf_error)
        return lines


# ------------------------------------------------------------------------------------------------
# Small formatting helpers (the templates get finished strings)
# ------------------------------------------------------------------------------------------------
def _float(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def fmt(v: Any, digits: int = 3) -> str:
    """A number with ``digits`` decimals, 'n/a' when undefined."""
    x = _float(v)
    return f"{x:.{digits}f}" if math.isfinite(x) else "n/a"


def pct(v: Any, digits: int = 1) -> str:
    x = _float(v)
    return f"{100 * x:.{digits}f}%" if math.isfinite(x) else "n/a"


def _ci(row: Mapping[str, Any], name: str, digits: int) -> str:
    lo, hi = _float(row.get(f"{name}_lo95")), _float(row.get(f"{name}_hi95"))
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return ""
    return f"[{lo:.{digits}f}, {hi:.{digits}f}]"




def _jsonable(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj


# ------------------------------------------------------------------------------------------------
# Sections
# ------------------------------------------------------------------------------------------------
def _requirement_results(registry: rq.Registry, path: Path | None, run: Path, warnings: list[str],
                         problems: list[str], check: RunCheck | None = None,
                         ) -> tuple[dict[str, rq.RequirementResult], dict[str, Any] | None]:
    """The requirement results of ``path`` and what they say about the gate.

    ``problems`` (each fails the gate) gets: results not bound to this run's digest, this code or this
    registry; a state that is not the one its own test outcomes give.
    """
    if path is None:
        warnings.append("no requirement test results were given: every requirement is 'not verified' "
                        f"(run: pytest -m requirements --uav-el-run {run} "
                        "--requirements-report <out>/requirements.json)")
        results = {r.id: rq.RequirementResult(r.id, r.title, rq.NOT_VERIFIED, "no test results given")
                   for r in registry}
        return results, None
    results, doc = rq.load_results(path, registry)
    ctx = doc.get("context") or {}
    if ctx.get("run") and Path(ctx["run"]).resolve() != run.resolve():
        warnings.append(f"the requirement results were produced on run {ctx['run']}, not on {run}")
    if check is not None:
        problems.extend(binding_problems(doc, check.digest, code_sha256(), registry.sha256, path))
    for rid, res in results.items():
        if not res.tests:
            if res.state != rq.NOT_VERIFIED:
                problems.append(f"{path}: {rid} is '{res.state}' with no test outcome behind it")
            continue
        own, _ = rq.requirement_state(res.tests)
        if own != res.state:
            problems.append(f"{path}: {rid} is '{res.state}' but its own test outcomes give '{own}'")
    if doc.get("collection_errors"):
        warnings.append(f"the test session had {len(doc['collection_errors'])} collection error(s): "
                        + "; ".join(doc["collection_errors"][:3]))
    if doc.get("ignored_ids"):
        warnings.append(f"ids in the test results that the registry lacks: {', '.join(doc['ignored_ids'])}")
    return results, doc


def binding_problems(doc: Mapping[str, Any], digest: str, code: str, registry_sha: str, path: Path) -> list[str]:
    """Why requirement results do not belong to this run, code and registry (empty when they do)."""
    ctx = doc.get("context") or {}
    out = []
    given = ctx.get("run_digest")
    if not given:
        out.append(f"{path}: the requirement results are not bound to a run (no run digest recorded)")
    elif given != digest:
        out.append(f"{path}: the requirement results were produced on other readouts (run digest {str(given)[:12]}, "
                   f"this run {digest[:12]})")
    if ctx.get("code_sha256") != code:
        out.append(f"{path}: the requirement results were produced on other code (code hash "
                   f"{str(ctx.get('code_sha256'))[:12]}, this checkout {code[:12]})")
    if (doc.get("registry") or {}).get("sha256") != registry_sha:
        out.append(f"{path}: the requirement results were produced with another requirement registry")
    return out


def _checks(registry: rq.Registry, man: Mapping[str, Any], images: Any, candidates: Any, table: Any,
            size: tuple[int, int] | None) -> dict[str, rq.Evidence]:
    p = registry.parameters
    out = {
        "EL-R04": rq.check_monitor_coverage(images, candidates),
        "EL-R08": rq.check_perturbation_coverage(images, p["required_perturbations"], p["min_images_per_perturbation"]),
        "EL-R09": rq.check_safety_gain(table, p["deployed_monitor"], p["required_perturbations"],
                                       p["min_images_per_perturbation"]),
        "EL-R10": rq.check_unsafe_landing_bound(table, p["deployed_monitor"], p["unsafe_landing_bound"],
                                                p["required_perturbations"], p["confidence"]),
        "EL-R12": rq.check_artefacts_identified(man),
        "EL-R13": rq.check_decision_time(images, p["deployed_monitor"], p["time_budget_s"]),
    }
    if size is not None:
        out["EL-R14"] = rq.check_pose_margin(man["config"]["core"], size, p["pose_error"])
    return {rid: ev for rid, ev in out.items() if rid in registry}


def _check_view(ev: rq.Evidence) -> dict[str, Any]:
    def cell(v: Any) -> str:
        if isinstance(v, bool):
            return "yes" if v else "no"
        if isinstance(v, float):
            return fmt(v, 4) if abs(v) < 10 else fmt(v, 1)
        return "n/a" if v is None else str(v)

    return {"id": ev.requirement, "name": ev.name, "status": STATUS_TEXT[ev.status],
            "status_class": STATUS_CLASS[ev.status], "summary": ev.summary,
            "columns": [c.replace("_", " ") for c in ev.columns],
            "rows": [[cell(r.get(c)) for c in ev.columns] for r in ev.rows[:60]],
            "more": f"{len(ev.rows) - 60} more rows in evidence.json" if len(ev.rows) > 60 else ""}


def _input_size(images: Any) -> tuple[int, int] | None:
    ok = images[images["fault"].fillna("") == ""] if len(images) else images
    if not len(ok):
        return None
    first = ok.iloc[0]
    return int(round(2 * float(first["default_x"]))), int(round(float(first["default_y"]) + float(first["default_r"])))


def _identity(run: Path, man: Mapping[str, Any], registry: rq.Registry, req_path: Path | None,
              req_doc: Mapping[str, Any] | None, csv_path: Path, templates: Path,
              check: RunCheck) -> tuple[list[dict], dict]:
    from assurance.campaign import git_commit

    weights = man.get("weights") or {}
    wpath = weights.get("path")
    current = ""
    if wpath and Path(wpath).is_file():
        current = "matches the file now" if sha256_file(wpath) == weights.get("sha256") else \
            "differs from the file now (it changed since the run)"
    elif wpath:
        current = "file no longer present"
    code = man.get("code") or {}
    code_sha, n_files = tree_sha256([ROOT / "el", ROOT / "assurance"])
    tpl_sha, n_tpl = tree_sha256([templates], base=templates.parent)
    data = man.get("data") or {}
    versions = man.get("versions") or {}
    cfg_sha = rq.config_sha256(man.get("config") or {})
    now_commit = git_commit()
    rows = [
        {"item": "Toolkit", "value": f"uav-el-assurance {code.get('version', '?')} (campaign); "
                                     f"{__version__} (this report)", "sha256": "", "note": ""},
        {"item": "Code (git)", "value": f"campaign: {code.get('git_commit') or 'unknown'}",
         "sha256": "", "note": f"report: {now_commit or 'unknown'}"},
        {"item": "Code (source tree)", "value": f"{n_files} source files of el/ and assurance/ at report time",
         "sha256": code_sha, "note": "a '-dirty' commit means uncommitted changes: rely on this hash"},
        {"item": "Weights", "value": str(wpath or "not recorded"), "sha256": weights.get("sha256") or "",
         "note": current},
        {"item": "Data", "value": f"{data.get('path', '?')} ({data.get('images', '?')} images)",
         "sha256": data.get("sha256") or "", "note": "hash of every image and label file (relative path and SHA-256)"},
        {"item": "Configuration", "value": "campaign configuration (manifest.json 'config', canonical JSON)",
         "sha256": cfg_sha, "note": ""},
        {"item": "Requirement registry", "value": str(registry.path), "sha256": registry.sha256, "note": ""},
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
             "requirements_results_path": str(req_path) if req_path else None,
             "requirements_results_sha256": sha256_file(req_path) if req_path else None,
             "results_csv_sha256": sha256_file(csv_path), "templates_sha256": tpl_sha,
             "manifest_sha256": sha256_file(run / "manifest.json"), "run_digest": check.digest,
             "run_shards_verified": not check.legacy, "versions": dict(versions)}
    return rows, ident


def _scene_types(scenes: Any, keys: Sequence[str]) -> tuple[str, bool]:
    styles: Counter[str] = Counter()
    lights: Counter[str] = Counter()
    synthetic = False
    for key in keys:
        sample = scenes.samples.get(key)
        if sample is None:
            continue
        try:
            meta = json.loads(sample.meta_path().read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        synthetic = True
        if meta.get("style"):
            styles[str(meta["style"])] += 1
        if meta.get("lighting"):
            lights[str(meta["lighting"])] += 1
    if not synthetic:
        return "no scene metadata found (meta/*.json): scene types unknown", False
    parts = []
    if styles:
        parts.append("styles: " + ", ".join(f"{k} ({v})" for k, v in sorted(styles.items())))
    if lights:
        parts.append("lighting: " + ", ".join(f"{k} ({v})" for k, v in sorted(lights.items())))
    return "synthetic scenes; " + ("; ".join(parts) if parts else "no style recorded"), True


def _domain(man: Mapping[str, Any], registry: rq.Registry, size: tuple[int, int] | None,
            checks: Mapping[str, rq.Evidence], scene_text: str, n_images: int) -> list[dict[str, str]]:
    cfg = man["config"]
    core = cfg["core"]
    pose, intr, safety = core["pose"], core["intrinsics"], core["safety"]
    pe = registry.parameters["pose_error"]
    margin = checks.get("EL-R14")
    need = margin.rows[0]["required_beta"] if margin and margin.rows else None
    rows = [
        {"name": "Height", "value": f"{pose['height_m']:g} m (nominal; errors up to {pe['height']:.0%} declared)"},
        {"name": "Pitch", "value": f"{pose['pitch_deg']:g} degrees below the horizon (errors up to {pe['pitch']:.0%})"},
        {"name": "Camera", "value": f"{intr.get('name', '?')}: sensor width {intr['sensor_width_mm']:g} mm, "
                                    f"focal length {intr['focal_mm']:g} mm, pinhole, square pixels"},
        {"name": "Images", "value": (f"{size[0]}x{size[1]} px, working resolution width {core['working_width']}"
                                     if size else f"working resolution width {core['working_width']}")},
        {"name": "Safety radius", "value": f"R = {safety['radius_m']:g} m, beta = {safety['beta']:g}"},
        {"name": "Required beta",
         "value": (f"{need:.3f} for height and pitch each off by up to {pe['height']:.0%} / {pe['pitch']:.0%} "
                   f"(el.camera.required_beta, worst case over the reachable rows): "
                   f"{'covered' if need <= safety['beta'] else 'NOT covered'} by beta = {safety['beta']:g}")
         if need is not None else "n/a (no evaluated image)"},
        {"name": "Landing area", "value": "top 2 of 10 image stripes never reachable; candidate discs wholly "
                                          f"inside the image; mode {core['mode']}, N* = {core['n_star']}"},
        {"name": "Scenes", "value": f"{n_images} test images; {scene_text}"},
        {"name": "Perturbations", "value": ", ".join(cfg["perturbations"]) + " at severit"
                                           + ("y " if len(cfg["severities"]) == 1 else "ies ")
                                           + ", ".join(str(s) for s in cfg["severities"])},
        {"name": "Monitor configurations", "value": ", ".join(cfg["monitors"]) + "; deployed: "
                                                    + registry.parameters["deployed_monitor"]},
        {"name": "Seeds", "value": f"campaign seed {cfg['seed']} (perturbations per image, MC dropout), "
                                   f"K-means seed {core['kmeans_seed']}"},
    ]
    return rows


def _matrix(registry: rq.Registry, results: Mapping[str, rq.RequirementResult],
            checks: Mapping[str, rq.Evidence], run: Path, csv_name: str) -> list[dict[str, Any]]:
    rows = []
    for req in registry:
        res = results[req.id]
        files = list(dict.fromkeys(t.nodeid.split("::")[0] for t in res.tests))
        artefacts = [f"test file {f}" for f in files]
        if "campaign" in req.verification_kind:
            artefacts.append(f"campaign run {run}")
        if req.id in ("EL-R09", "EL-R10"):
            artefacts.append(f"results table {csv_name}")
        if req.id == "EL-R12":
            artefacts.append("evidence.json (identity) and this report")
        check = checks.get(req.id)
        rows.append({
            "id": req.id, "title": req.title, "method": req.verification_method, "acceptance": req.acceptance,
            "state": res.state, "state_class": STATE_CLASS[res.state], "reason": res.reason,
            "short_reason": _short_reason(res),
            "tests": [{"nodeid": t.nodeid, "outcome": t.outcome,
                       "outcome_class": ("verified" if t.outcome in rq.PASSING else
                                         "failed" if t.outcome in rq.FAILING else "not-verified"),
                       "message": t.message[:300]} for t in res.tests],
            "artefacts": artefacts,
            "check": (f"campaign check: {STATUS_TEXT[check.status]}: {check.summary}" if check else ""),
        })
    return rows


def _short_reason(res: rq.RequirementResult) -> str:
    """The state's reason without the test details (the tests column shows them)."""
    if not res.tests:
        return res.reason
    n = len(res.tests)
    counts = Counter(t.outcome for t in res.tests)
    return ", ".join(f"{k} {v}" for v, k in sorted(((v, k) for k, v in counts.items()), reverse=True)) + f" (of {n})"


RESULT_FIGURES = (("g_cm", "G_CM", 3), ("g_rm", "G_RM", 3), ("g_star", "G*", 3), ("mcc", "MCC", 3),
                  ("f1", "F1", 3), ("precision", "Precision", 3), ("recall", "Recall", 3), ("fp_rate", "FP rate", 3),
                  ("overhead_s", "Overhead (s)", 3))


def _results_view(table: Any, deployed: str, bound: float) -> dict[str, Any]:
    headers = ["Scenario", "Monitor", "Img.", "Cand."] + [h for _, h, _ in RESULT_FIGURES] + [
        "Unsafe landings", "UB95"]
    rows = []
    last = None
    for rec in table.to_dict("records"):
        scen = f"{rec['perturbation']} (s{int(rec['severity'])})"
        n = int(rec["images"])
        k = int(round(_float(rec["unsafe_landing_rate"]) * n)) if n and math.isfinite(
            _float(rec["unsafe_landing_rate"])) else 0
        ub = _float(rec["unsafe_landing_ub95"])
        cells = [{"v": fmt(rec[name], d), "ci": _ci(rec, name, d), "over": False} for name, _, d in RESULT_FIGURES]
        cells.append({"v": f"{k}/{n}", "ci": pct(rec["unsafe_landing_rate"]), "over": False})
        cells.append({"v": pct(ub), "ci": "", "over": bool(math.isfinite(ub) and ub > bound)})
        rows.append({"scenario": scen if scen != last else "", "first": scen != last, "monitor": rec["monitor"],
                     "deployed": rec["monitor"] == deployed, "images": str(n),
                     "candidates": str(int(rec["candidates"])), "faults": int(rec.get("faults") or 0), "cells": cells})
        last = scen
    return {"headers": headers, "rows": rows}


def _sample_size(table: Any, registry: rq.Registry, n_boot: int) -> list[str]:
    p = registry.parameters
    bound, conf = float(p["unsafe_landing_bound"]), float(p["confidence"])
    n = table["images"].to_numpy(int)
    if not len(n):
        return ["The run holds no evaluated image: it shows nothing."]
    n_min, n_max = int(n.min()), int(n.max())
    ub0 = clopper_pearson_upper(0, n_min, conf)
    need = rq.images_needed(bound, conf)
    dep = table[table["monitor"] == p["deployed_monitor"]]
    k_tot = int(round((dep["unsafe_landing_rate"].astype(float) * dep["images"]).sum())) if len(dep) else 0
    n_tot = int(dep["images"].sum()) if len(dep) else 0
    size = f"{n_min}" if n_min == n_max else f"{n_min} to {n_max}"
    paras = [
        f"Each scenario (perturbation x monitor configuration) holds {size} test images. The unsafe-landing "
        f"rate comes with an exact one-sided {conf:.0%} upper bound (Clopper-Pearson): with 0 unsafe landings "
        f"in {n_min} images the rate can still be as high as {ub0:.1%}, so such a sample cannot show a rate "
        f"below that. Showing the configured bound of {bound:.1%} (EL-R10) needs at least {need} images per "
        "scenario with no unsafe landing; more if any occurs.",
        f"Over all scenarios of the deployed monitor ({p['deployed_monitor']}) there were {k_tot} unsafe "
        f"landing(s) in {n_tot} decisions (the scenarios share their test images, so these are not "
        "independent trials; the per-scenario bounds are the ones to read).",
        f"Gains, monitor metrics and overhead carry 95% percentile-bootstrap intervals over images ({n_boot} "
        "resamples, fixed seed; one set of resampled images for every figure of a scenario). They describe "
        "the sampling variability of these test images only: they say nothing about scene types, cameras, "
        "poses, weather or sensor faults the campaign did not contain. Monitor metrics are pooled over "
        "candidates; the candidates of one image are correlated, which resampling whole images respects. "
        "An 'n/a' is an undefined ratio (e.g. precision when the monitor rejected nothing), never a zero.",
    ]
    faults = int(table["faults"].sum()) if "faults" in table else 0
    if faults:
        paras.append(f"{faults} image evaluation(s) ended in a recorded fault and are left out of the figures "
                     "(see the run's readouts).")
    return paras


def _limitations(man: Mapping[str, Any], registry: rq.Registry, results: Mapping[str, rq.RequirementResult],
                 synthetic: bool, table: Any) -> list[str]:
    from assurance.perturbations import PERTURBATIONS, SEVERITIES
    from el.monitors import PAPER_GRID

    cfg = man["config"]
    out = []
    if synthetic:
        out.append("The test scenes are synthetic (the project's procedural generator in the UAVid layout), not "
                   "real UAV footage. The figures transfer to real flights only as far as the scenes' realism "
                   "does (materials, shadows, look-alike classes, people and cars); a campaign on real labelled "
                   "footage (UAVid or the applicant's own) is needed before any operational claim.")
    else:
        out.append("The provenance of the test data is as recorded in the manifest; this report cannot tell "
                   "whether the images represent the intended operations.")
    out.append("Geometry assumes flat ground, a pinhole camera without lens distortion and a known nominal pose; "
               "slopes, roofs as landing surfaces, and pose errors beyond the declared box are outside the domain. "
               "The default action's landing area is a proxy (a disc at the bottom centre of the image).")
    out.append("Timings (overhead, decision time) were measured on the campaign's machine "
               f"({(man.get('versions') or {}).get('platform', 'unknown')}) and are not those of the flight computer.")
    missing_p = [p for p in PERTURBATIONS if p not in cfg["perturbations"]]
    if missing_p:
        out.append("Perturbations not evaluated: " + ", ".join(missing_p) + ".")
    missing_s = [str(s) for s in SEVERITIES if s not in cfg["severities"]]
    if missing_s:
        out.append("Severities not evaluated: " + ", ".join(missing_s) + ".")
    missing_m = [m for m in PAPER_GRID if m not in cfg["monitors"]]
    if missing_m:
        out.append(f"{len(missing_m)} of the paper's {len(PAPER_GRID)} monitor configurations were not evaluated.")
    out.append("Not tested at all: night, rain, snow, glare, lens dirt beyond the listed perturbations; moving "
               "people and vehicles between the image and the landing; wind drift under the parachute; the "
               "flight controller's execution of the manoeuvre.")
    for rid, res in results.items():
        if res.state == rq.NOT_VERIFIED:
            out.append(f"{rid} ({registry[rid].title}) is not verified: {res.reason}.")
    return out


def _baseline(baseline: Path, man: Mapping[str, Any], ident: Mapping[str, Any], table: Any,
              results: Mapping[str, rq.RequirementResult], registry: rq.Registry,
              baseline_requirements: Path | None, n_boot: int) -> dict[str, Any]:
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
            a, b = _float(rec.get(f"{f}_base")), _float(rec.get(f))
            d = b - a
            cls = ""
            if math.isfinite(d) and abs(d) > 1e-12:
                better = (d > 0) == HIGHER_IS_BETTER[f]
                cls = "better" if better else "worse"
            cells.append({"base": fmt(a), "now": fmt(b), "delta": (f"{d:+.3f}" if math.isfinite(d) else ""),
                          "cls": cls})
        rows.append({"scenario": f"{rec['perturbation']} (s{int(rec['severity'])})", "monitor": rec["monitor"],
                     "status": status, "cells": cells})
    req_changes: list[dict[str, str]] = []
    req_note = ""
    if baseline_requirements is not None:
        bres, _ = rq.load_results(baseline_requirements, registry)
        for rid, res in results.items():
            old = bres[rid].state
            if old != res.state:
                req_changes.append({"id": rid, "title": res.title, "baseline": old, "current": res.state,
                                    "baseline_class": STATE_CLASS[old], "current_class": STATE_CLASS[res.state]})
        req_note = (f"{len(req_changes)} requirement state(s) changed since the baseline "
                    f"({baseline_requirements})." if req_changes else
                    f"No requirement changed state since the baseline ({baseline_requirements}).")
    else:
        req_note = ("The baseline's requirement results were not given (--baseline-requirements): "
                    "state changes cannot be shown.")
    return {"run": str(baseline), "identity": identity, "figures": [f.replace("_", " ") for f in figs],
            "rows": rows, "requirements": req_changes, "requirements_note": req_note}


def _pick_examples(images: Any, deployed: str) -> list[tuple[Any, str]]:
    present = [m for m in dict.fromkeys(images["monitor"]) if m]
    if deployed not in present and present:  # a run without the deployed configuration: its first one
        deployed = present[0]
    ok = images[(images["fault"].fillna("") == "") & (images["monitor"] == deployed)]
    if not len(ok):
        return []
    order = ok.assign(_clean=(ok["perturbation"] != "none")).sort_values(["_clean", "perturbation", "key"],
                                                                          kind="stable")
    picks: list[tuple[Any, str]] = []
    wants = (
        (lambda r: r["action"] == "land" and int(r["selected"]) == 0 and not r["decision_unsafe"],
         "landing on the top-ranked candidate, accepted by the monitor"),
        (lambda r: r["action"] == "land" and int(r["selected"]) > 0 and not r["decision_unsafe"],
         "landing after the monitor rejected higher-ranked candidates"),
        (lambda r: r["action"] == "default", "default action (parachute)"),
    )
    for test, why in wants:
        for _, r in order.iterrows():
            if test(r):
                picks.append((r, why))
                break
    return picks


def _unsafe(images: Any) -> tuple[list[tuple[Any, str]], dict[tuple, list[str]], int]:
    """One picture per (scenario, image, landing candidate) with an unsafe landing, for every monitor."""
    ok = images[(images["fault"].fillna("") == "") & images["decision_unsafe"].astype(bool)]
    groups: dict[tuple, list[str]] = {}
    first: dict[tuple, Any] = {}
    for _, r in ok.sort_values(["perturbation", "severity", "key", "monitor"], kind="stable").iterrows():
        key = (r["perturbation"], int(r["severity"]), r["key"], int(r["selected"]))
        groups.setdefault(key, []).append(str(r["monitor"]))
        first.setdefault(key, r)
    picks = [(first[k], "") for k in groups]
    return picks, groups, len(ok)


# ------------------------------------------------------------------------------------------------
# Rendering
# ------------------------------------------------------------------------------------------------
FAULTS_CSV = "faults.csv"


def _faults(out: Path, warnings: list[str]) -> list[dict[str, str]] | None:
    """The fault-injection table (``uav-el fault-table``) found next to the report, for its appendix."""
    from assurance.fault_injection import read_table

    path = out / FAULTS_CSV
    if not path.is_file():
        return None
    try:
        return read_table(path)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        warnings.append(f"{path}: fault-injection table not shown: {exc}")
        return None


def environment(templates: str | Path | None = None) -> Any:
    """The Jinja2 environment of the report: autoescape on for every template, strict undefined."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined

    return Environment(loader=FileSystemLoader(str(templates or TEMPLATES_DIR)), autoescape=True,
                       undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)


def render_html(context: Mapping[str, Any], templates: str | Path | None = None) -> str:
    return environment(templates).get_template(TEMPLATE).render(**context)


def rel(path: str | Path | None) -> str | None:
    """A path relative to the project root when it lies under it (as written elsewhere otherwise)."""
    if path is None:
        return None
    p = Path(path)
    try:
        return p.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return str(path)


PDF_VARIANT = "pdf/a-3b"


def write_pdf(html: str, path: Path, attachments: Sequence[Path] = ()) -> str | None:
    """Write the PDF/A-3b of ``html`` (WeasyPrint) with ``attachments`` embedded; returns None, or why no
    PDF was written."""
    try:
        with warnings.catch_warnings():  # e.g. "HarfBuzz-Subset will be required by future versions"
            warnings.simplefilter("ignore", DeprecationWarning)
            from weasyprint import HTML
    except Exception as exc:  # ImportError, or OSError when the Pango library is missing
        return f"PDF not written: WeasyPrint cannot be loaded ({type(exc).__name__}: {exc}); {PDF_HINT}"
    from weasyprint import Attachment

    tmp = path.with_name(f".{path.name}.tmp")
    try:
        files = [Attachment(filename=str(a), name=a.name, description=f"{a.name} of this evidence report",
                            relationship="Data" if a.suffix in (".json", ".csv", ".xml") else "Supplement")
                 for a in attachments if a.is_file()]
        HTML(string=html, base_url=str(path.parent)).write_pdf(str(tmp), pdf_variant=PDF_VARIANT, attachments=files)
        tmp.replace(path)
    except Exception as exc:
        tmp.unlink(missing_ok=True)
        return f"PDF not written: WeasyPrint failed ({type(exc).__name__}: {exc})"
    return None


def pdf_attachment_names(path: str | Path) -> list[str]:
    """Names of the files embedded in a PDF (its EmbeddedFiles name tree), read without a PDF library:
    the objects are searched in the file and in its compressed object streams."""
    import re
    import zlib

    data = Path(path).read_bytes()
    chunks = [data]
    for m in re.finditer(rb"stream\r?\n", data):
        try:
            chunks.append(zlib.decompressobj().decompress(data[m.end():m.end() + 4_000_000]))
        except zlib.error:
            continue
    names: list[str] = []
    for chunk in chunks:
        for m in re.finditer(rb"/Type\s*/Filespec(.{0,400}?)>>", chunk, re.S):
            f = re.search(rb"/UF\s*\((.*?)\)|/F\s*\((.*?)\)", m.group(1))
            if f:
                names.append((f.group(1) or f.group(2)).decode("latin-1"))
    return list(dict.fromkeys(names))


TRACE_COLUMNS = ("requirement", "test", "outcome", "state", "artefact")


def traceability_rows(registry: rq.Registry, results: Mapping[str, rq.RequirementResult], run: Path,
                      csv_path: Path) -> list[dict[str, str]]:
    """One row per (requirement, claiming test): outcome, the requirement's state, the artefact it read."""
    rows = []
    for req in registry:
        res = results[req.id]
        campaign = "campaign" in req.verification_kind
        for t in res.tests or [None]:
            test_file = t.nodeid.split("::")[0] if t else ""
            artefact = (rel(csv_path) if req.id in ("EL-R09", "EL-R10") else rel(run)) if campaign else test_file
            rows.append({"requirement": req.id, "test": t.nodeid if t else "", "outcome": t.outcome if t else "",
                         "state": res.state, "artefact": artefact or ""})
    return rows


def _write_csv_rows(path: Path, rows: Sequence[Mapping[str, str]], columns: Sequence[str]) -> None:
    import csv
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    _write(path, buf.getvalue())


def _write(path: Path, text: str) -> None:
    from el.uavid import atomic_write_bytes

    atomic_write_bytes(path, text.encode("utf-8"))


WAIVER_FIELDS = ("id", "reason", "tracked_by", "owner", "expires")


def load_waivers(path: str | Path) -> dict[str, dict[str, str]]:
    """Accepted deviations: requirement id -> {reason, tracked_by, owner, expires} (``assurance/waivers.yaml``).

    ``expires`` is a date (YYYY-MM-DD: the waiver holds until the end of that day) or a toolkit version
    (X.Y.Z: it holds for versions before that one). ValueError naming the file for a malformed file, an
    entry without one of the fields, an expiry that is neither, or a requirement waived twice.
    """
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: unreadable waivers file: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("waivers") or [], list):
        raise ValueError(f"{path}: a waivers file is a mapping with a list 'waivers'")
    out: dict[str, dict[str, str]] = {}
    for i, w in enumerate(data.get("waivers") or []):
        if not isinstance(w, dict) or not all(str(w.get(k) or "").strip() for k in WAIVER_FIELDS):
            raise ValueError(f"{path}: waiver {i + 1} needs an id, a reason, tracked_by, an owner and expires "
                             "(a date YYYY-MM-DD or a version X.Y.Z)")
        expires = str(w["expires"]).strip()
        _expiry(expires, path, i)
        rid = str(w["id"])
        if rid in out:
            raise ValueError(f"{path}: {rid} is waived twice")
        out[rid] = {"reason": " ".join(str(w["reason"]).split()), "tracked_by": str(w["tracked_by"]),
                    "owner": str(w["owner"]), "expires": expires}
    return out


def _version_tuple(text: str) -> tuple[int, ...]:
    return tuple(int(x) for x in text.split("."))


def _expiry(expires: str, path: Path, i: int) -> tuple[str, Any]:
    import re

    if re.fullmatch(r"\d{4}-\d{2}-\d{2}", expires):
        try:
            return "date", _dt.date.fromisoformat(expires)
        except ValueError:
            pass
    elif re.fullmatch(r"\d+(\.\d+){0,2}", expires):
        return "version", _version_tuple(expires)
    raise ValueError(f"{path}: waiver {i + 1}: expires must be a date YYYY-MM-DD or a version X.Y.Z, got {expires!r}")


def waiver_expired(waiver: Mapping[str, str], *, today: _dt.date | None = None, version: str = __version__) -> bool:
    """Whether a waiver no longer holds: its date has passed, or this toolkit's version reached its version."""
    kind, value = _expiry(waiver["expires"], Path("waivers"), 0)
    if kind == "date":
        return (today or _dt.datetime.now(_dt.UTC).date()) > value
    return _version_tuple(version) >= value


def generate(
    run: str | Path,
    out: str | Path,
    *,
    requirements: str | Path | None = None,
    baseline: str | Path | None = None,
    baseline_requirements: str | Path | None = None,
    registry: str | Path | None = None,
    strict: bool = False,
    waivers: str | Path | None = None,
    pdf: bool = True,
    n_boot: int = 2000,
    templates: str | Path | None = None,
) -> EvidenceReport:
    """Write the evidence report of ``run`` into ``out`` and return what the gate says.

    ``requirements``: the plugin's results JSON; None looks for ``out/requirements.json`` and, without
    one, leaves every requirement "not verified". ``baseline``: an earlier run to compare with;
    ``baseline_requirements``: that run's results JSON (for requirement state changes).
    """
    from assurance.evidence_gallery import Scenes, decision_examples, perturbation_gallery
    from assurance.evidence_plots import gains_figure, monitor_metrics_figure, overhead_figure, roc_figure
    from assurance.perturbations import PAPER_PERTURBATIONS

    run, out = Path(run), Path(out)
    templates = Path(templates) if templates else TEMPLATES_DIR
    if not (templates / TEMPLATE).is_file():
        raise FileNotFoundError(f"{templates / TEMPLATE}: report template not found")
    warnings: list[str] = []
    reg = rq.load_registry(registry)
    params = reg.parameters
    deployed = params["deployed_monitor"]
    man = readouts.read_manifest(run)
    check = verify_run(run).raise_if_damaged()
    if check.legacy:
        warnings.append(f"{run}: written before shard hashes: its readouts cannot be verified")
    if baseline:
        verify_run(baseline).raise_if_damaged()
    images = readouts.load_table(run, "images")
    candidates = readouts.load_table(run, "candidates")
    table = results_table(run, n_boot=n_boot)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "results.csv"
    write_csv(table, csv_path)

    req_path = Path(requirements) if requirements else (out / "requirements.json")
    if requirements is None and not req_path.is_file():
        req_path = None
    problems: list[str] = []
    results, req_doc = _requirement_results(reg, req_path, run, warnings, problems, check)
    size = _input_size(images)
    checks = _checks(reg, man, images, candidates, table, size)
    for rid, ev in checks.items():
        state = results[rid].state
        if state == rq.VERIFIED and ev.status != rq.PASS:  # a claim this report can refute: never passes
            problems.append(f"{rid}: the test results say verified, this report's own check of the run says "
                            f"{STATUS_TEXT[ev.status]} ({ev.summary})")
        elif ev.status == rq.PASS and state == rq.FAILED:
            warnings.append(f"{rid}: the test results ({state}) disagree with the campaign check on this run "
                            f"({STATUS_TEXT[ev.status]}): were they produced on another run?")
    if deployed not in man["config"]["monitors"]:
        warnings.append(f"the deployed monitor {deployed!r} (registry) was not evaluated by this campaign")

    identity_rows, ident = _identity(run, man, reg, req_path, req_doc, csv_path, templates, check)
    scenes = Scenes(man["data"]["path"], man["config"]["seed"])
    if scenes.error:
        warnings.append(scenes.error)
    ok = images[images["fault"].fillna("") == ""] if len(images) else images
    keys = sorted(set(ok["key"])) if len(ok) else []
    scene_text, synthetic = _scene_types(scenes, keys)

    gallery_perts = list(dict.fromkeys(list(PAPER_PERTURBATIONS) + list(man["config"]["perturbations"])))
    gallery = perturbation_gallery(scenes, keys[0] if keys else None, gallery_perts)
    examples = decision_examples(scenes, images, candidates, _pick_examples(images, deployed)) if len(ok) else []
    unsafe_picks, unsafe_groups, n_unsafe = _unsafe(images) if len(ok) else ([], {}, 0)
    unsafe = decision_examples(scenes, images, candidates, unsafe_picks, width=360, also=unsafe_groups,
                               compact=True)

    plots = []
    if len(table):
        plots.append({"title": "Safety gain per perturbation and monitor configuration",
                      "uri": gains_figure(table, deployed)})
        plots.append({"title": "Runtime monitor: precision, recall, false-positive rate",
                      "uri": monitor_metrics_figure(table, deployed)})
        plots.append({"title": "Runtime-monitor overhead",
                      "uri": overhead_figure(images, list(man["config"]["monitors"]), params["time_budget_s"],
                                             deployed)})
        roc = roc_figure(candidates, list(man["config"]["monitors"]), deployed)
        if roc is not None:
            plots.append({"title": "Runtime-monitor scores: ROC curves and operating points", "uri": roc})

    states = {rid: r.state for rid, r in results.items()}
    counts = rq.summary_counts(states.values())
    failed = [rid for rid, s in states.items() if s == rq.FAILED]
    not_verified = [rid for rid, s in states.items() if s == rq.NOT_VERIFIED]
    waiver_list = load_waivers(waivers) if waivers else {}
    expired = {rid for rid, w in waiver_list.items() if waiver_expired(w)}
    problems += [f"the waiver of {rid} (owner: {waiver_list[rid]['owner']}) expired ({waiver_list[rid]['expires']})"
                 for rid in sorted(expired)]
    waived = [rid for rid in failed if rid in waiver_list and rid not in expired and not strict]
    base = (_baseline(Path(baseline), man, ident, table, results, reg,
                      Path(baseline_requirements) if baseline_requirements else None, n_boot)
            if baseline else None)
    created = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    blocking = [rid for rid in failed if rid not in waived]
    gate = "FAILED" if blocking or problems else ("WAIVED" if waived else "INCOMPLETE" if not_verified else "PASSED")
    gate_text = (f"{len(failed)} requirement(s) failed" + (f", {len(waived)} waived" if waived else "")
                 if failed else
                 f"{len(not_verified)} requirement(s) not verified" if not_verified else
                 "every requirement verified")
    if problems:
        gate_text = f"{len(problems)} integrity problem(s) (below); " + gate_text
    cfg = man["config"]
    commands = [
        f"uav-el campaign --data {man['data']['path']} --out {run} --perturbations {' '.join(cfg['perturbations'])} "
        f"--severities {' '.join(str(s) for s in cfg['severities'])} --monitors "
        + " ".join(f"'{m}'" for m in cfg["monitors"])
        + (f" --images {cfg['images']}" if cfg.get("images") else "") + f" --seed {cfg['seed']}"
        + (f" --weights {cfg['weights']}" if cfg.get("weights") else ""),
        f"pytest -m requirements --uav-el-run {run} --requirements-report {out / 'requirements.json'}",
        f"uav-el evidence --run {run} --out {out}" + (f" --requirements {req_path}" if req_path else ""),
    ]
    context = {
        "title": "Evidence report: UAV emergency landing",
        "run_name": run.name, "run": str(run), "created": created,
        "gate": gate, "gate_class": {"FAILED": "failed", "WAIVED": "failed", "INCOMPLETE": "not-verified",
                                     "PASSED": "verified"}[gate],
        "gate_text": gate_text,
        "waivers": [{"id": rid, **waiver_list[rid]} for rid in waived],
        "problems": problems,
        "counts": [{"state": s, "n": counts[s], "cls": STATE_CLASS[s],
                    "ids": ", ".join(f"{rid} (failed, waived)" if rid in waived else rid
                                     for rid, st in states.items() if st == s)} for s in rq.STATES],
        "warnings": warnings,
        "identity": identity_rows,
        "domain": _domain(man, reg, size, checks, scene_text, len(keys)),
        "domain_text": [{"name": k.replace("_", " "), "value": v} for k, v in reg.operating_domain.items()],
        "parameters": [{"name": k.replace("_", " "), "value": (", ".join(map(str, v)) if isinstance(v, list) else
                                                                ", ".join(f"{a} {b:.0%}" for a, b in v.items())
                                                                if isinstance(v, dict) else str(v))}
                       for k, v in params.items()],
        "matrix": _matrix(reg, results, checks, run, csv_path.name),
        "requirements": [{"id": r.id, "title": r.title, "text": r.text, "rationale": r.rationale,
                          "source": "; ".join(r.source), "method": r.verification_method,
                          "acceptance": r.acceptance, "domain": r.domain} for r in reg],
        "sources": [{"key": k, "text": " ".join(v.split())} for k, v in reg.sources.items()],
        "checks": [_check_view(ev) for ev in checks.values()],
        "results": _results_view(table, deployed, float(params["unsafe_landing_bound"])),
        "deployed": deployed, "bound": pct(params["unsafe_landing_bound"]),
        "sample_size": _sample_size(table, reg, n_boot),
        "plots": plots,
        "gallery": gallery, "gallery_key": keys[0] if keys else "",
        "examples": examples, "unsafe": unsafe, "n_unsafe": n_unsafe, "n_unsafe_pictures": len(unsafe),
        "scenes_error": scenes.error,
        "limitations": _limitations(man, reg, results, synthetic, table),
        "baseline": base,
        "commands": commands,
        "faults": _faults(out, warnings),
    }
    html = render_html(context, templates)
    html_path, json_path, pdf_path = out / "evidence.html", out / "evidence.json", out / "evidence.pdf"
    trace_path, junit_path, sums_path = out / "traceability.csv", out / "junit.xml", out / "SHA256SUMS"
    faults_path = out / FAULTS_CSV
    _write(html_path, html)
    _write_csv_rows(trace_path, traceability_rows(reg, results, run, csv_path), TRACE_COLUMNS)
    if pdf_path.exists():
        pdf_path.unlink()  # never leave a PDF of an earlier report beside this one
    pdf_error = None if pdf else "PDF not written (--no-pdf)"

    def finish(pdf_error: str | None) -> int:
        exit_code = 1 if blocking or problems or (strict and (not_verified or pdf_error)) else 0
        doc = _doc(pdf_error, exit_code)
        _write(json_path, json.dumps(_jsonable(doc), indent=2, allow_nan=False) + "\n")
        files = (html_path, pdf_path, json_path, csv_path, trace_path, junit_path, faults_path)
        sums = [(p, sha256_file(p)) for p in files if p.is_file()]
        _write(sums_path, "".join(f"{h}  {p.name}\n" for p, h in sums))
        return exit_code

    def _doc(pdf_error: str | None, exit_code: int) -> dict[str, Any]:
        return {
            "format": EVIDENCE_FORMAT, "created": created, "run": rel(run), "strict": strict,
            "gate": {"result": gate, "exit_code": exit_code, "counts": counts, "failed": failed,
                     "waived": {rid: waiver_list[rid] for rid in waived}, "not_verified": not_verified,
                     "problems": problems},
            "identity": ident,
            "parameters": params,
            "requirements": {rid: {**results[rid].to_dict(), "text": reg[rid].text, "source": list(reg[rid].source),
                                   "acceptance": reg[rid].acceptance} for rid in reg.ids},
            "checks": {ev.requirement: {"name": ev.name, "status": ev.status, "summary": ev.summary,
                                        "rows": list(ev.rows)} for ev in checks.values()},
            "results": table.to_dict("records"),
            "unsafe_landings": n_unsafe,
            "baseline": base and {k: v for k, v in base.items() if k != "figures"},
            "warnings": warnings,
            "files": {"html": rel(html_path), "pdf": None if pdf_error else rel(pdf_path), "csv": rel(csv_path),
                      "traceability": rel(trace_path), "junit": rel(junit_path) if junit_path.is_file() else None,
                      "faults": rel(faults_path) if context["faults"] else None},
            "pdf_error": pdf_error,
        }

    exit_code = finish(pdf_error)  # the JSON says the PDF will be there; rewritten if it could not be
    if pdf:
        pdf_error = write_pdf(html, pdf_path, [json_path, csv_path, trace_path, junit_path, sums_path]
                              + ([faults_path] if context["faults"] else []))
        exit_code = finish(pdf_error)
    return EvidenceReport(out=out, html=html_path, json=json_path, pdf=None if pdf_error else pdf_path,
                          pdf_error=pdf_error, states=states, exit_code=exit_code, warnings=warnings,
                          problems=problems, waived=waived)
