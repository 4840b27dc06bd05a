"""The evidence report's inputs (the run, its tables, the requirement results, the report's own checks) and the
finished context its templates render."""

from __future__ import annotations

import shlex
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from assurance import requirements as rq
from assurance.analysis.floor import monitor_floor
from assurance.analysis.table import results_table, write_csv
from assurance.campaign import readouts
from assurance.campaign.attestation import UnattestedRunError, check_run_attestation
from assurance.campaign.integrity import RunCheck, verify_run
from assurance.campaign.label_pin import label_problems
from assurance.campaign.model_files import changed_model_files
from assurance.campaign.perturbation_plan import default_plan, system_plan
from assurance.campaign.presets import preset_config
from assurance.dataio.layouts import data_source
from assurance.evidence.domain_section import frame_gate_view, mark_outside, odd_rows
from assurance.evidence.facts import report_facts
from assurance.evidence.gallery import Scenes, decision_examples, perturbation_gallery
from assurance.evidence.gate import GATE_CLASS, Gate, requirement_results, weakening_problems
from assurance.evidence.identity import identity
from assurance.evidence.matrix import check_problems, check_view, matrix, run_checks
from assurance.evidence.options import ReportOptions
from assurance.evidence.render import TEMPLATES_DIR, fault_case_count, faults_table, rel
from assurance.evidence.safe_strips import safe_class_strips
from assurance.evidence.sections import (
    domain,
    floor_limitation,
    limitations,
    pick_examples,
    refused_frames,
    required_beta,
    results_view,
    run_scenarios,
    sample_size,
    scene_types,
    ub_label,
    unsafe_picks,
)
from assurance.evidence.text import STATE_CLASS, pct
from el.base.hashing import sha256_file
from el.classes.labels import UAVID
from el.flight.pipeline import DEPLOYED_GATE


@dataclass
class Inputs:
    """What the report reads: the run and its tables, the registry, the requirement results, its own checks."""

    run: Path
    out: Path
    templates: Path
    registry: rq.Registry
    manifest: dict[str, Any]
    check: RunCheck
    images: Any
    candidates: Any
    table: Any
    csv_path: Path
    req_path: Path | None
    results: dict[str, rq.RequirementResult]
    req_doc: dict[str, Any] | None
    checks: dict[str, rq.Evidence]
    warnings: list[str]
    problems: list[str]
    system: Any = None  # the system file assessed (assurance.system.SystemFile)
    attestation: Any = None  # the run's verified signed statement (assurance.campaign.attestation.RunAttestation)
    results_signed_by: str | None = None  # the keyid that signed the requirement results, when verified
    facts: Any = None  # what the report states about the system (assurance.evidence.facts.ReportFacts)

    @property
    def deployed(self) -> str:
        """The deployed monitor configuration (the registry's parameter)."""
        return self.registry.parameters["deployed_monitor"]


def read_inputs(run: Path, out: Path, options: ReportOptions) -> Inputs:
    """Read and verify the run (and the baseline's shards), write ``results.csv``, read the requirement results
    and run the report's checks; a damaged run raises ``readouts.DamagedRunError``. With ``trusted`` keys, the
    run's signed statement must verify against one of them and match the files
    (``UnattestedRunError`` naming what does not). The report's facts about the system (``facts``) are built here,
    once, from the system file, the run's manifest and its readouts (and the ``waivers`` file the gate reads).
    ``options``: the report's, with the system file's waivers, templates and targets already resolved."""
    o = options
    requirements, baseline, registry, n_boot, templates = o.requirements, o.baseline, o.registry, o.n_boot, o.templates
    system, targets, targets_source, trusted, waivers = o.system, o.targets, o.targets_source, o.trusted, o.waivers
    templates = Path(templates) if templates else TEMPLATES_DIR
    if not templates.is_dir():
        raise FileNotFoundError(f"{templates}: report template folder not found")
    warnings: list[str] = []
    reg = (registry if isinstance(registry, rq.Registry) else rq.load_registry(registry)).with_targets(
        targets, source=targets_source)
    man = readouts.read_manifest(run)
    check = verify_run(run).raise_if_damaged()
    attestation = None
    if trusted is not None:
        attestation = check_run_attestation(run, trusted)
        if not attestation.ok:
            raise UnattestedRunError(run, attestation.problems)
    if check.legacy:
        warnings.append(f"{run}: written before shard hashes: its readouts cannot be verified")
    if baseline:
        verify_run(baseline).raise_if_damaged()
    images = readouts.load_table(run, "images")
    candidates = readouts.load_table(run, "candidates")
    facts = report_facts(system, man, images, size=readouts.input_size(images), waivers=waivers)
    reg = reg.for_system(facts.texts)  # the texts about the system assessed: its camera, pose, domain, classes
    table = results_table(run, n_boot=n_boot)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "results.csv"
    write_csv(table, csv_path)
    req_path = Path(requirements) if requirements else (out / "requirements.json")
    if requirements is None and not req_path.is_file():
        req_path = None
    problems: list[str] = weakening_problems(reg, system)
    results, req_doc = requirement_results(reg, req_path, run, warnings, problems, check)
    ctx = rq.CheckContext(run, reg.parameters, n_boot=n_boot, manifest=man, images=images, candidates=candidates,
                          table=table)
    checks = run_checks(reg, ctx)
    check_problems(checks, results, problems, warnings)
    problems.extend(system_problems(system, man, req_doc, run))
    pinned, unpinned = label_problems(system, man, attestation.predicate if attestation is not None else None, run)
    problems.extend(pinned)  # the label set or class hierarchy changed since the run (label_pin)
    warnings.extend(unpinned)
    problems.extend(check.missing_problems())  # tasks the manifest names with no readouts
    changed, unchecked = changed_model_files(man.get("model_files"))
    problems.extend(changed)
    if unchecked:
        warnings.append(f"model files of the run not found here, so not checked: {', '.join(unchecked)}")
    deployed = reg.parameters["deployed_monitor"]
    if deployed not in man["config"]["monitors"]:
        warnings.append(f"the deployed monitor {deployed!r} (registry) was not evaluated by this campaign")
    return Inputs(run, out, templates, reg, man, check, images, candidates, table, csv_path, req_path, results,
                  req_doc, checks, warnings, problems, system, attestation, facts=facts)


def system_problems(system: Any, man: dict[str, Any], req_doc: dict[str, Any] | None, run: Path) -> list[str]:
    """Why the report, the run and the requirement results are not about one system file (empty when they are):
    a run records the system file it assessed; the requirement results record the run's."""
    recorded = (man.get("system") or {}).get("sha256")
    if system is None or not recorded:
        return []
    out = []
    if recorded != system.sha256:
        out.append(f"{run}: the campaign assessed another system file (SHA-256 {recorded[:12]}, "
                   f"{(man.get('system') or {}).get('path') or 'the embedded default'}) than this report "
                   f"({system.label}, {system.sha256[:12]}); give the run's system file with --system")
    if req_doc is not None and (req_doc.get("context") or {}).get("system_sha256") != recorded:
        out.append("the requirement results are not bound to the run's system file (system SHA-256 "
                   f"{str((req_doc.get('context') or {}).get('system_sha256'))[:12]}, the run's {recorded[:12]})")
    return out


def _setting(inp: Inputs, key: str, default: str) -> str:
    return str(inp.system.get(key, default)) if inp.system is not None else default


def system_view(inp: Inputs) -> dict[str, Any] | None:
    """The system file the report assesses: where, its hash, every value it sets, the model's hash."""
    if inp.system is None:
        return None
    sysf = inp.system
    weights = inp.manifest.get("weights") or {}
    return {"label": sysf.label if sysf.path is None else str(rel(sysf.path)), "sha256": sysf.sha256,
            "name": sysf.name, "values": [{"key": k, "value": v} for k, v in sysf.values()],
            "model_sha256": weights.get("sha256") or "not recorded",
            "model": weights.get("path") or weights.get("model") or "a model object handed to the campaign (no file "
                                                                    "recorded)"}


def _ships_gate(man: Mapping[str, Any]) -> bool:
    """Whether the run deployed the shipped frame gate (whose validation study the package carries)."""
    gate = (man.get("config") or {}).get("gate") or {}
    return bool(gate) and DEPLOYED_GATE.is_file() and gate.get("sha256") == sha256_file(DEPLOYED_GATE)


def _plots(inp: Inputs) -> list[dict[str, str]]:
    """The report's figures (none for an empty results table)."""
    from assurance.evidence.plots import (
        gains_figure,
        monitor_metrics_figure,
        overhead_figure,
        roc_figure,
    )  # deferred: matplotlib, off verify/land paths

    table, deployed, monitors = inp.table, inp.deployed, list(inp.manifest["config"]["monitors"])
    if not len(table):
        return []
    plots = [{"title": "Safety gain per perturbation and monitor configuration",
              "uri": gains_figure(table, deployed)},
             {"title": "Runtime monitor: precision, recall, false-positive rate",
              "uri": monitor_metrics_figure(table, deployed)},
             {"title": "Runtime-monitor overhead",
              "uri": overhead_figure(inp.images, monitors, inp.registry.parameters["time_budget_s"], deployed)}]
    roc = roc_figure(inp.candidates, monitors, deployed)
    if roc is not None:
        plots.append({"title": "Runtime-monitor scores: ROC curves and operating points", "uri": roc})
    return plots


def signature_row(attestation: Any) -> dict[str, str]:
    """The identity row of the run's signature: the signer's key fingerprint, or why there is none."""
    if attestation is None:
        return {"item": "Campaign signature", "value": "not checked (report written without trusted keys)",
                "sha256": "", "note": "uav-el evidence checks it against --trusted-keys"}
    return {"item": "Campaign signature", "value": f"in-toto statement over the task list and every shard, "
                                                   f"verified ({attestation.path.name})",
            "sha256": attestation.keyid or "", "note": "the SHA-256 of the signer's Ed25519 public key "
                                                       "(its fingerprint: uav-el keys)"}


def results_signature_row(inp: Inputs) -> dict[str, str]:
    """The identity row of the requirement results' signature."""
    if inp.attestation is None:
        value, fp = "not checked (report written without trusted keys)", ""
    elif inp.req_path is None:
        value, fp = "no requirement results given", ""
    elif inp.results_signed_by:
        value, fp = "statement of uav-el verify over requirements.json and junit.xml, verified", inp.results_signed_by
    else:
        value, fp = "not verified: see the gate problems (results are evidence only as uav-el verify signed them)", ""
    return {"item": "Requirement results signature", "value": value, "sha256": fp,
            "note": "pinned: run digest, campaign statement, registry, targets, waivers, system file"}


def campaign_context(inp: Inputs) -> dict[str, Any]:
    """The run's part of the context: identity, operating domain, pictures, plots, results and limitations."""
    man, images, candidates, reg = inp.manifest, inp.images, inp.candidates, inp.registry
    own = inp.system is not None and not inp.system.default
    identity_rows, ident = identity(inp, templates=TEMPLATES_DIR,
                                    origins=inp.system.target_origins() if own else None)
    identity_rows[:0] = [signature_row(inp.attestation), results_signature_row(inp)]
    ident["campaign_signed_by"] = inp.attestation.keyid if inp.attestation is not None else None
    ident["results_signed_by"] = inp.results_signed_by
    scenes = Scenes(data_source(man["data"]), man["config"]["seed"])
    if scenes.error:
        inp.warnings.append(scenes.error)
    ok = images[images["fault"].fillna("") == ""] if len(images) else images
    keys = sorted(set(ok["key"])) if len(ok) else []
    scene_text, synthetic = scene_types(scenes, keys)
    picks, groups, n_unsafe = unsafe_picks(images) if len(ok) else ([], {}, 0)
    unsafe = decision_examples(scenes, images, candidates, picks, width=360, also=groups, compact=True)
    params = reg.parameters
    need_beta = required_beta(man, images, readouts.input_size(images), params["pose_error"])
    return {
        "ident": ident, "synthetic": synthetic,
        "identity": identity_rows,
        "domain": domain(man, reg, readouts.input_size(images), scene_text, len(keys), inp.facts, need_beta),
        "odd": odd_rows(man, images, reg.parameters["pose_error"], need_beta),
        "frame_gates": frame_gate_view() if _ships_gate(man) else None,
        "gallery": perturbation_gallery(scenes, keys[0] if keys else None, run_scenarios(man["config"])),
        "gallery_key": keys[0] if keys else "",
        "safe_strips": _safe_strips(inp, scenes, keys),
        "examples": (decision_examples(scenes, images, candidates, pick_examples(images, inp.deployed))
                     if len(ok) else []),
        "unsafe": unsafe, "n_unsafe": n_unsafe, "n_unsafe_pictures": len(unsafe),
        "n_unsafe_deployed": _unsafe_of(ok, inp.deployed),
        "scenes_error": scenes.error,
        "plots": _plots(inp),
        "results": mark_outside(results_view(inp.table, inp.deployed, float(params["unsafe_landing_bound"]),
                                             float(params["confidence"])), inp.table, man),
        "deployed": inp.deployed, "bound": pct(params["unsafe_landing_bound"]),
        "confidence": rq.confidence_text(params["confidence"]), "ub_label": ub_label(params["confidence"]),
    }


def _safe_strips(inp: Inputs, scenes: Any, keys: list[str]) -> dict[str, Any]:
    """What each safe class of the system's label set covers in the run's own frames (first page:
    ``assurance.evidence.safe_strips``)."""
    if inp.system is None:
        labels = UAVID
    else:
        labels = inp.system.labels()
    return safe_class_strips(scenes.samples, keys, labels)


VALUE_FLAGS = ("-m", "-p", "--rootdir", "--junitxml", "--uav-el-run", "--uav-el-report", "--uav-el-registry",
               "--uav-el-targets", "--uav-el-waivers", "--uav-el-system")


def extra_tests(req_doc: Mapping[str, Any] | None) -> list[str]:
    """The requirement tests ``uav-el verify --tests`` added to the packaged suite (from the results' pytest
    arguments)."""
    args = list(((req_doc or {}).get("context") or {}).get("args") or [])
    out, skip = [], False
    for a in args:
        if skip:
            skip = False
        elif a in VALUE_FLAGS:
            skip = True
        elif not str(a).startswith("-") and not str(a).replace("\\", "/").endswith("requirements/suite"):
            out.append(str(a))
    return out


def _data_option(inp: Inputs) -> str:
    """The campaign's ``--data``: none when the run read the system file's ``[data] test`` table as it is now (a
    recorded spec keeps its layout, split list and poses file, which ``--data FOLDER`` would drop), else the
    folder, with the spec's keys said when it recorded one the system file no longer gives."""
    data = inp.manifest["data"]
    spec = data.get("spec")
    if not spec:
        return f" --data {data['path']}"
    if inp.system is not None and not inp.system.default:
        try:
            now = inp.system.data("test")
        except ValueError:  # SystemFileError: [data] test unset, a bad table or a missing folder
            now = None
        if now is not None and hasattr(now, "to_dict") and {**now.to_dict(), "path": str(Path(now).resolve())} == spec:
            return ""  # the system file's [data] test: the same spec
    keys = ", ".join(f"{k} = {v!r}" for k, v in spec.items() if k != "path")
    return f" --data {data['path']} (the run read it as a [data] test table with {keys}: give that table)"


def commands(inp: Inputs, accepted: tuple[str, ...] = ()) -> list[str]:
    """The commands that reproduce the run, the requirement results and this report (with the system file, the
    added requirement tests and the accepted deviations they were made with, ``NAME=VALUE`` each)."""
    run, out, cfg = inp.run, inp.out, inp.manifest["config"]
    src = inp.registry.targets_source
    tfile = src if inp.registry.targets and src and Path(src).suffix == ".json" else None
    system = f" --system {inp.system.label}" if inp.system is not None and not inp.system.default else ""
    tests = extra_tests(inp.req_doc)
    return [
        f"uav-el campaign{system}{_data_option(inp)} --out {run} --perturbations "
        f"{' '.join(cfg['perturbations'])}"  # capped severities (a declared maximum below 3): the preset's, not given
        + ("" if cfg.get("severity_caps") else f" --severities {' '.join(str(s) for s in cfg['severities'])}")
        + " --monitors "
        + " ".join(f"'{m}'" for m in cfg["monitors"])
        + (f" --images {cfg['images']}" if cfg.get("images") else "") + f" --seed {cfg['seed']}"
        + (f" --weights {cfg['weights']}" if cfg.get("weights") and not system else ""),
        f"uav-el verify {run} --out {out}{system}" + (f" --tests {' '.join(tests)}" if tests else "")
        + (f" --targets {tfile}" if tfile else ""),
        f"uav-el evidence --run {run} --out {out}{system}"
        + (f" --requirements {inp.req_path}" if inp.req_path else "")
        + (f" --targets {tfile}" if tfile else "")
        + "".join(f" --accept-deviation {shlex.quote(a)}" for a in accepted),  # NAME=VALUE: the values it binds
    ]


def images_per_perturbation(inp: Inputs) -> int:
    """The fewest images evaluated without a fault under any perturbation of the run (0 for none)."""
    ok = inp.images[inp.images["fault"].fillna("") == ""] if inp.images is not None and len(inp.images) else None
    return int(ok.groupby("perturbation")["key"].nunique().min()) if ok is not None and len(ok) else 0


def decisive_images(inp: Inputs) -> int:
    """The images per perturbation from which the run size no longer limits a requirement: the release preset's for
    the shipped system, else the fewest that can show the unsafe-landing bound (``rq.images_needed``)."""
    release = preset_config("release").images
    if (inp.system is None or inp.system.default) and release is not None:
        return release
    p = inp.registry.parameters
    return rq.images_needed(float(p["unsafe_landing_bound"]), float(p["confidence"]))


DECIDED_BY = {"calibration_card": "a calibration card decides it (uav-el calibrate, named in the system file's "
                                  "[monitor] calibration)"}
"""What decides a requirement whose check reads an unset parameter: no run size does."""


def not_size_limited(inp: Inputs) -> dict[str, str]:
    """The registry's ``size_limited`` requirements that no run size decides here (a parameter their check reads is
    unset, e.g. no calibration card), each with what decides it."""
    out = {}
    for rid in inp.registry.parameters.get("size_limited") or []:
        unset = [n for c in rq.checks_of(rid) for n in c.parameters if n in DECIDED_BY
                 and not inp.registry.parameters.get(n)]
        if unset:
            out[rid] = DECIDED_BY[unset[0]]
    return out


def undecidable_here(inp: Inputs) -> list[str]:
    """The registry's ``size_limited`` requirements when the run is smaller than :func:`decisive_images`, else none:
    the only ones whose 'not verified' does not fail the gate (one no run size decides is not among them)."""
    if images_per_perturbation(inp) >= decisive_images(inp):
        return []
    failed = {ev.requirement for ev in inp.checks.values() if ev.status == "fail"}  # shown missed at any size
    return [rid for rid in _limited_by_size(inp) if rid not in failed]


def _limited_by_size(inp: Inputs) -> list[str]:
    """The registry's ``size_limited`` requirements but those no run size decides here (:func:`not_size_limited`)."""
    other = not_size_limited(inp)
    return [rid for rid in inp.registry.parameters.get("size_limited") or [] if rid not in other]


def run_scope(inp: Inputs, states: dict[str, str]) -> dict[str, Any] | None:
    """For a run smaller than :func:`decisive_images` (e.g. the demo): its size, the requirements it leaves
    undecided, those no run size decides (and what does), and the command that decides them; None otherwise."""
    n = images_per_perturbation(inp)
    if n >= decisive_images(inp):
        return None
    other, limited = not_size_limited(inp), set(_limited_by_size(inp))
    undecided = [rid for rid, st in states.items() if st == rq.NOT_VERIFIED and rid in limited]
    p = inp.registry.parameters
    bound, conf = float(p["unsafe_landing_bound"]), float(p["confidence"])
    return {"images": n, "undecided": ", ".join(undecided),
            "other": "; ".join(f"{rid} is left not verified at any run size: {why}" for rid, why in other.items()
                               if states.get(rid) == rq.NOT_VERIFIED),
            **_decide_command(inp), "bound": pct(bound), "confidence": rq.confidence_text(conf),
            "bound_images": rq.images_needed(bound, conf),
            "bound_claims": ", ".join(rq.requirements_reading("unsafe_landing_bound")) or "the bound"}


def _decide_command(inp: Inputs) -> dict[str, str]:
    """The command that decides every requirement: the release target for the shipped system, else a campaign of
    the system's own file on every frame of its data, under its perturbations (its preset's default,
    ``assurance.campaign.perturbation_plan.system_plan``; ``--perturbations`` only when the registry requires one the
    file does not bring), named when they are not the shipped six, into a new run folder beside this one (a
    campaign into this one would resume it, and refuses another configuration)."""
    if inp.system is None or inp.system.default:
        return {"command": "make release-evidence", "about": "about 12 minutes on 2 cores"}
    need = decisive_images(inp)
    planned = [p.name for p in system_plan(inp.system)]
    missing = [p for p in inp.registry.parameters.get("required_perturbations") or [] if p not in planned]
    names = planned + missing
    flag = f" --perturbations {' '.join(names)}" if missing else ""
    shipped = names == [p.name for p in default_plan()]
    return {"command": f"uav-el campaign --system {inp.system.label} --out {inp.run}-full{flag} (a new run folder; "
                       f"at least {need} frames per perturbation in its [data] test)",
            "about": "" if shipped else f"under {', '.join(names)}: the system's declared and required "
                                         "perturbations"}


def _design_time_scope(inp: Inputs) -> list[str]:
    """What the design-time requirements were checked on, for a system other than the shipped one."""
    if inp.system is None or inp.system.default:
        return []
    ids = [r.id for r in inp.registry if "test" in r.verification_kind and "campaign" not in r.verification_kind]
    if not ids:
        return []
    return [f"{', '.join(ids)} are properties of the flight code, verified by the packaged design tests on the "
            "toolkit's own small synthetic scenes (oblique Phantom-class camera, its own torch network), not on "
            f"this system's network, camera or label set ({inp.registry.facts.get('label_set', '')}); their "
            "'verified' says the code holds them, not that this system was measured against them."]


def _unsafe_of(ok: Any, monitor: str) -> int | None:
    """The unsafe decisions of one configuration among judged image rows; None when the run did not fly it."""
    mine = ok[ok["monitor"] == monitor] if len(ok) else ok
    return int(mine["decision_unsafe"].astype(bool).sum()) if len(mine) else None


def template_context(inp: Inputs, gate: Gate, campaign: dict[str, Any], base: dict[str, Any] | None,
                     created: str, n_boot: int) -> dict[str, Any]:
    """Everything the templates show, as finished strings and records."""
    reg, results = inp.registry, inp.results
    counts = rq.summary_counts(gate.states.values())
    return {
        "title": _setting(inp, "report.title", "Evidence report: UAV emergency landing"),
        "organisation": _setting(inp, "report.organisation", ""),
        "system": system_view(inp),
        "run_name": inp.run.name, "run": str(inp.run), "created": created,
        "gate": gate.result, "gate_class": GATE_CLASS[gate.result], "gate_text": gate.text,
        "waivers": [{"id": rid, **gate.waivers[rid]} for rid in gate.waived],
        "problems": inp.problems,
        "counts": [{"state": s, "n": counts[s], "cls": STATE_CLASS[s],
                    "ids": ", ".join(f"{rid} (failed, waived)" if rid in gate.waived else rid
                                     for rid, st in gate.states.items() if st == s)} for s in rq.STATES],
        "warnings": inp.warnings,
        "scope": run_scope(inp, gate.states),
        "identity": campaign["identity"],
        "domain": campaign["domain"], "odd": campaign["odd"], "frame_gates": campaign["frame_gates"],
        "domain_text": [{"name": k.replace("_", " "), "value": v} for k, v in reg.operating_domain.items()],
        "facts": inp.facts.view(), "frame_gate": inp.facts.frame_gate,
        "matrix": matrix(reg, results, inp.checks, inp.run, inp.csv_path.name),
        "requirements": [{"id": r.id, "title": r.title, "text": r.text, "rationale": r.rationale,
                          "source": "; ".join(r.source), "method": r.verification_method,
                          "acceptance": r.acceptance, "domain": r.domain} for r in reg],
        "sources": [{"key": k, "text": " ".join(v.split())} for k, v in reg.sources.items()],
        "checks": [check_view(ev) for ev in inp.checks.values()],
        "results": campaign["results"],
        "deployed": campaign["deployed"], "bound": campaign["bound"],
        "confidence": campaign["confidence"], "ub_label": campaign["ub_label"],
        "sample_size": sample_size(inp.table, reg, n_boot),
        "plots": campaign["plots"],
        "gallery": campaign["gallery"], "gallery_key": campaign["gallery_key"],
        "safe_strips": campaign["safe_strips"],
        "examples": campaign["examples"], "unsafe": campaign["unsafe"], "n_unsafe": campaign["n_unsafe"],
        "n_unsafe_deployed": campaign["n_unsafe_deployed"],
        "n_unsafe_pictures": campaign["n_unsafe_pictures"],
        "scenes_error": campaign["scenes_error"],
        "limitations": limitations(inp.manifest, reg, results, campaign["synthetic"], inp.table, inp.facts)
        + floor_limitation(monitor_floor(inp.images, inp.candidates), refused_frames(inp.images))
        + _design_time_scope(inp),
        "baseline": base,
        "commands": commands(inp),
        "faults": faults_table(inp.out, inp.warnings), "fault_cases": fault_case_count(),
    }
