"""Sections of the evidence report computed from the run: operating domain, results, sample size, limitations,
example decisions."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any

from assurance import requirements as rq
from assurance.analysis.metrics import clopper_pearson_upper
from assurance.campaign.task import scenario_pairs
from assurance.dataio.poses import read_meta
from assurance.evidence.text import ci, fmt, pct, to_float
from assurance.perturbations import PERTURBATIONS, SEVERITIES, TRAITS
from el.geometry.odd import OUTSIDE_ODD
from el.monitors import PAPER_GRID
from el.monitors.frame_gate import OUT_OF_DOMAIN


def scene_types(scenes: Any, keys: Sequence[str]) -> tuple[str, bool]:
    """What the scenes were (styles and lighting from their meta JSON), and whether they are synthetic."""
    styles: Counter[str] = Counter()
    lights: Counter[str] = Counter()
    synthetic = False
    for key in keys:
        sample = scenes.samples.get(key)
        if sample is None:
            continue
        try:
            meta = read_meta(sample.meta_path())  # bounded: data folders are not signed
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


def domain(man: Mapping[str, Any], registry: rq.Registry, size: tuple[int, int] | None, scene_text: str,
           n_images: int, facts: Any, need: float | None) -> list[dict[str, str]]:
    """The operating domain the run covered: pose and where each frame's came from, camera, images, safety radius
    and its margin (``need``: the required beta, :func:`required_beta`), the stripes that may hold a landing,
    scenes (``facts``: ``assurance.evidence.facts``)."""
    cfg = man["config"]
    core = cfg["core"]
    pose, safety = core["pose"], core["safety"]
    pe = registry.parameters["pose_error"]
    where = " at the nominal pose and each frame's own" if getattr(facts, "own_poses", None) else ""
    rows = [
        *_pose_rows(pose, pe, facts),
        {"name": "Pose source", "value": facts.pose_source},
        {"name": "Camera", "value": facts.camera},
        {"name": "Images", "value": (f"{size[0]}x{size[1]} px, working resolution width {core['working_width']}"
                                     if size else f"working resolution width {core['working_width']}")},
        {"name": "Safety radius", "value": f"R = {safety['radius_m']:g} m, beta = {safety['beta']:g}"},
        {"name": "Required beta",
         "value": (f"{need:.3f} for height and pitch each off by up to {pe['height']:.0%} / {pe['pitch']:.0%} "
                   f"(el.geometry.camera.required_beta, worst case over the reachable rows"
                   f"{where}): "
                   f"{'covered' if need <= safety['beta'] else 'NOT covered'} by beta = {safety['beta']:g}")
         if need is not None else "n/a (no evaluated image)"},
        {"name": "Landing area", "value": f"{facts.stripes}; candidate discs wholly inside the image; mode "
                                          f"{core['mode']}, N* = {core['n_star']}"},
        {"name": "Scenes", "value": f"{n_images} test images; {scene_text}"},
        {"name": "Perturbations", "value": perturbations_text(cfg)},
        {"name": "Monitor configurations", "value": ", ".join(cfg["monitors"]) + "; deployed: "
                                                    + registry.parameters["deployed_monitor"]},
        {"name": "Seeds", "value": f"campaign seed {cfg['seed']} (perturbations per image, MC dropout), "
                                   f"K-means seed {core['kmeans_seed']}"},
    ]
    return rows


def required_beta(man: Mapping[str, Any], images: Any, size: tuple[int, int] | None,
                  pose_error: Mapping[str, float]) -> float | None:
    """The beta the pose-error box requires at the run's input size, worst over the nominal pose and each frame's
    own (what the pose-margin requirement compares beta with); None without an evaluated image."""
    if size is None:
        return None
    return rq.worst_required_beta(man["config"]["core"], size, rq.own_poses(images), pose_error)


def _pose_rows(pose: Mapping[str, Any], pe: Mapping[str, float], facts: Any) -> list[dict[str, str]]:
    """Height and pitch as evaluated: the nominal pose, or the range of the frames' own poses (``facts.own_poses``)
    with the declared errors around each frame's own pose."""
    own = getattr(facts, "own_poses", None)
    if not own:
        return [{"name": "Height", "value": f"{pose['height_m']:g} m (nominal; errors up to {pe['height']:.0%} "
                                             "declared)"},
                {"name": "Pitch", "value": f"{pose['pitch_deg']:g} degrees below the horizon (errors up to "
                                            f"{pe['pitch']:.0%})"}]

    def span(lo: float, hi: float) -> str:
        return f"{lo:g}" if lo == hi else f"{lo:g} to {hi:g}"

    src = f"each frame's own pose, from {facts.poses_from}"
    return [{"name": "Height", "value": f"{span(*own['height_m'])} m ({src}; errors up to {pe['height']:.0%} "
                                         "declared around each frame's own height)"},
            {"name": "Pitch", "value": f"{span(*own['pitch_deg'])} degrees below the horizon ({src}; errors up to "
                                        f"{pe['pitch']:.0%} around each frame's own pitch)"}]


def ub_label(conf: float) -> str:
    """The results table's header of the upper bound at ``conf`` (``UB95``, ``UB99``, ``UB97.5``)."""
    return "UB" + rq.confidence_text(conf).rstrip("%")


RESULT_FIGURES = (("g_cm", "G_CM", 3), ("g_rm", "G_RM", 3), ("g_star", "G*", 3), ("mcc", "MCC", 3),
                  ("f1", "F1", 3), ("precision", "Precision", 3), ("recall", "Recall", 3), ("fp_rate", "FP rate", 3),
                  ("overhead_s", "Overhead (s)", 3))


def results_view(table: Any, deployed: str, bound: float, conf: float) -> dict[str, Any]:
    """The results table as the report shows it: figures with their intervals, the deployed monitor marked, and
    the unsafe-landing rate's one-sided upper bound at ``conf`` (the registry's confidence parameter, not the
    table's fixed 95%)."""
    headers = ["Scenario", "Monitor", "Img.", "Cand."] + [h for _, h, _ in RESULT_FIGURES] + [
        "Unsafe landings", ub_label(conf)]
    rows = []
    last = None
    for rec in table.to_dict("records"):
        scen = f"{rec['perturbation']} (s{int(rec['severity'])})"
        n = int(rec["images"])
        k = int(round(to_float(rec["unsafe_landing_rate"]) * n)) if n and math.isfinite(
            to_float(rec["unsafe_landing_rate"])) else 0
        ub = clopper_pearson_upper(k, n, conf) if n and math.isfinite(to_float(rec["unsafe_landing_rate"])) \
            else math.nan
        cells = [{"v": fmt(rec[name], d), "ci": ci(rec, name, d), "over": False} for name, _, d in RESULT_FIGURES]
        cells.append({"v": f"{k}/{n}", "ci": pct(rec["unsafe_landing_rate"]), "over": False})
        cells.append({"v": pct(ub), "ci": "", "over": bool(math.isfinite(ub) and ub > bound)})
        rows.append({"scenario": scen if scen != last else "", "first": scen != last, "monitor": rec["monitor"],
                     "deployed": rec["monitor"] == deployed, "images": str(n),
                     "candidates": str(int(rec["candidates"])), "faults": int(rec.get("faults") or 0), "cells": cells})
        last = scen
    return {"headers": headers, "rows": rows}


def sample_size(table: Any, registry: rq.Registry, n_boot: int) -> list[str]:
    """What the sample can show: paragraphs on the bounds and intervals the run's image counts allow."""
    p = registry.parameters
    claims = ", ".join(rq.requirements_reading("unsafe_landing_bound"))
    claims = f" ({claims})" if claims else ""
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
        f"rate comes with an exact one-sided {rq.confidence_text(conf)} upper bound (Clopper-Pearson): with 0 "
        f"unsafe landings in {n_min} images the rate can still be as high as {ub0:.1%}, so such a sample cannot "
        f"show a rate below that. Showing the configured bound of {bound:.1%}{claims} needs at least {need} images per "
        "scenario with no unsafe landing; more if any occurs.",
        f"Over all scenarios of the deployed monitor ({p['deployed_monitor']}) there were {k_tot} unsafe "
        f"landing(s) in {n_tot} decisions (the scenarios share their test images, so these are not "
        "independent trials; the per-scenario bounds are the ones to read).",
        f"Gains, monitor metrics and overhead carry 95% BCa bootstrap intervals over images (bias-corrected and "
        f"accelerated; the percentile interval of the same resamples where BCa is undefined; {n_boot} "
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


def limitations(man: Mapping[str, Any], registry: rq.Registry, results: Mapping[str, rq.RequirementResult],
                 synthetic: bool, table: Any, facts: Any) -> list[str]:
    """What the evidence does not cover: synthetic scenes, geometry, timings, what was not evaluated or verified."""
    cfg = man["config"]
    out = []
    if synthetic:
        out.append("The test scenes are synthetic (the project's procedural generator in the UAVid layout), not "
                   "real UAV footage. The figures transfer to real flights only as far as the scenes' realism "
                   "does (materials, shadows, look-alike classes, people and cars); a campaign on real labelled "
                   "footage (UAVid or the applicant's own) is needed before any operational claim.")
    else:
        declared = (f"as the system file declares it ([data] provenance: {facts.data_provenance})"
                    if facts.data_provenance else "not declared (no scene meta, no [data] provenance)")
        out.append(f"The provenance of the test data is {declared}; this report cannot tell whether the images "
                   "represent the intended operations.")
    known = ("a known pose per frame (each frame's own, from "
             f"{facts.poses_from})" if getattr(facts, "own_poses", None) else "a known nominal pose")
    out.append(f"Geometry assumes flat ground, a pinhole camera without lens distortion and {known}; "
               "slopes, roofs as landing surfaces, and pose errors beyond the declared box are outside the domain. "
               "The default action's landing area is a proxy: a disc on the ground below the UAV (its nadir point "
               "when the frame shows it, else the nearest ground the frame shows, at the bottom centre).")
    out.append("Timings (overhead, decision time) were measured on the campaign's machine "
               f"({(man.get('versions') or {}).get('platform', 'unknown')}) and are not those of the flight computer.")
    missing_p = [p for p in PERTURBATIONS if p not in cfg["perturbations"]]
    if missing_p:
        out.append("Perturbations not evaluated: " + ", ".join(missing_p) + ".")
    run = {sev for _, sev in run_scenarios(cfg)}
    missing_s = [str(s) for s in SEVERITIES if s not in run]
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


REFUSED_PREFIXES = (OUTSIDE_ODD, OUT_OF_DOMAIN)
"""Reasons of a default action taken before any candidate is walked: outside the declared domain, or refused by the
frame gate (``el.geometry.odd``, ``el.monitors.frame_gate``)."""


def refused_frames(images: Any) -> int:
    """How many judged frames (perturbation, severity, image) ended in the default action before any walk: outside
    the declared domain or refused by the frame gate (the same for every configuration)."""
    if images is None or not len(images) or "reason" not in images:
        return 0
    ok = images[images["fault"].fillna("") == ""].drop_duplicates(["perturbation", "severity", "key"])
    return int(ok["reason"].astype(str).str.startswith(REFUSED_PREFIXES).sum())


def floor_limitation(floor: Any, refused: int = 0) -> list[str]:
    """The sentence on what no monitor can prevent (``assurance.analysis.floor.monitor_floor``'s table), when any
    frame is on the floor: there every decision is unsafe, so no monitor, however good, would have saved it.
    ``refused``: frames whose default action came before any walk (:func:`refused_frames`), said as the cause."""
    if floor is None or not len(floor) or not int(floor["floor"].sum()):
        return []
    parts = [f"{int(r.floor)} of {int(r.images)} {r.perturbation} (s{int(r.severity)})"
             for r in floor.itertuples() if int(r.floor)]
    cause = ("fewer needs a better network, more candidates or another default action, not a better monitor" if not
             refused else f"{refused} frame(s) judged were refused before any landing (outside the declared domain "
             "or by the frame gate), where the default action is the design's answer; elsewhere fewer needs a "
             "better network, more candidates or another default action, not a better monitor")
    return [f"What no monitor can prevent: in {int(floor['floor'].sum())} of the {int(floor['images'].sum())} frames "
            f"judged ({'; '.join(parts)}) no candidate is truly safe (or there is none) and the default area is "
            "unsafe too, so every configuration, a perfect monitor included, lands unsafely there. The unsafe "
            f"landings in the results count them; {cause}."]


def pick_examples(images: Any, deployed: str) -> list[tuple[Any, str]]:
    """Example decisions of the deployed monitor (a run without it: its first configuration): a top-ranked
    landing, a landing after rejections, a default."""
    present = [m for m in dict.fromkeys(images["monitor"]) if m]
    if deployed not in present and present:
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


def unsafe_picks(images: Any) -> tuple[list[tuple[Any, str]], dict[tuple, list[str]], int]:
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


def run_scenarios(cfg: Mapping[str, Any]) -> list[tuple[str, int]]:
    """The (perturbation, severity) pairs a run's configuration (the manifest's ``config``) evaluated: its severities,
    a perturbation declared with a lower maximum (``severity_caps``) at those up to it."""
    return scenario_pairs(cfg["perturbations"], cfg["severities"], cfg.get("severity_caps"))


def _severity_text(sevs: Sequence[int]) -> str:
    return ("severity " if len(sevs) == 1 else "severities ") + ", ".join(str(s) for s in sevs)


def perturbations_text(cfg: Mapping[str, Any]) -> str:
    """The perturbations a run evaluated and at which severities, each as it ran (a capped one at its own)."""
    by: dict[str, list[int]] = {}
    for name, sev in run_scenarios(cfg):
        by.setdefault(name, []).append(sev)
    common = [int(x) for x in cfg["severities"]]
    alike = [n for n, sevs in by.items() if sevs == common or not TRAITS[n].graded]
    other = [f"{n} at {_severity_text(sevs)} (its declared maximum)" for n, sevs in by.items() if n not in alike]
    return "; ".join(([f"{', '.join(alike)} at {_severity_text(common)}"] if alike else []) + other)

