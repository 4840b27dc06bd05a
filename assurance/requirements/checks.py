"""The campaign checks: plain functions of a run's readouts, results table or manifest (docs/architecture.md 4.6).

Each returns an ``Evidence`` record (pass, fail or insufficient) and knows nothing of requirement ids:
``assurance.requirements.catalogue`` ties each to its requirement (``@check``) and the registry's
parameters. The determinism checks (re-run, recomputation) are in ``determinism``.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from assurance.analysis.intervals import BOUND_MET, BOUND_MISSED, clopper_pearson_upper, decide_rate_bound
from assurance.requirements.records import FAIL, INSUFFICIENT, PASS, Evidence
from el.flight.kernel import REFUSALS
from el.geometry.camera import required_beta, working_size
from el.geometry.config import CoreConfig
from el.monitors.spec import walk_of
from el.monitors.walk import walk_order


def _ok_images(images: Any) -> Any:
    if images is None or len(images) == 0:
        return images
    return images[images["fault"].fillna("") == ""]


def _num(v: Any) -> float | None:
    """A plain float for records (None for NaN, so JSON stays valid)."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def check_monitor_coverage(images: Any, candidates: Any) -> Evidence:
    """EL-R04 on campaign readouts: every 'land' decision is on an accepted candidate, every candidate
    walked before it (in the configuration's walk order, ``el.monitors.walk``) was rejected, and the two
    readout tables agree on the decision. A frame the kernel refuses before the walk (outside the declared domain,
    or above the frame gate's threshold: ``el.flight.kernel.REFUSALS``) is the default action by design, not a breach.

    ``images`` / ``candidates``: the run's tables (``assurance.campaign.readouts.load_table``).
    """
    name = "monitor coverage of every decision"
    ok = _ok_images(images)
    if ok is None or len(ok) == 0:
        return Evidence(name, INSUFFICIENT, "no evaluated image in the readouts")
    groups: dict[tuple, Any] = {}
    if candidates is not None and len(candidates):
        for key, g in candidates.groupby(["perturbation", "severity", "monitor", "key"], sort=False):
            groups[key] = g.sort_values("rank")
    violations: list[dict[str, Any]] = []
    lands = 0
    for row in ok.itertuples(index=False):
        key = (row.perturbation, row.severity, row.monitor, row.key)
        g = groups.get(key)
        n = 0 if g is None else len(g)
        accepted = np.zeros(0, bool) if g is None else g["accepted"].to_numpy(bool)
        scores = g["score"].to_numpy(float) if g is not None and "score" in g.columns else np.zeros(n)
        order = walk_order(list(scores), walk_of(row.monitor)) if n else []
        flagged = np.zeros(0, bool) if g is None else g["selected"].to_numpy(bool)
        ranks = np.zeros(0, int) if g is None else g["rank"].to_numpy(int)
        sel = int(row.selected)
        problem = ""
        if int(row.candidates) != n:
            problem = f"images table says {int(row.candidates)} candidates, candidates table has {n}"
        elif row.action == "land":
            lands += 1
            if not 0 <= sel < n:
                problem = f"landed on candidate {sel}, which does not exist"
            elif not accepted[sel]:
                problem = f"landed on candidate {sel}, which the monitor rejected"
            elif any(accepted[k] for k in order[:order.index(sel)]):
                first = next(k for k in order if accepted[k])
                problem = f"landed on candidate {sel} although candidate {first}, walked before, was accepted"
            elif not np.array_equal(flagged, ranks == sel):
                problem = "candidates table disagrees with the images table on the selected candidate"
        else:
            if flagged.any():
                problem = "default action but a candidate is flagged as selected"
            elif accepted.any() and not str(row.reason).startswith(REFUSALS):  # refused whatever the monitor said
                problem = f"default action although candidate {int(np.flatnonzero(accepted)[0])} was accepted"
        if problem:
            violations.append({"perturbation": row.perturbation, "severity": int(row.severity),
                               "monitor": row.monitor, "image": row.key, "action": row.action, "problem": problem})
    cols = ("perturbation", "severity", "monitor", "image", "action", "problem")
    if violations:
        return Evidence(name, FAIL, f"{len(violations)} decision(s) of {len(ok)} break monitor coverage "
                        f"({lands} landings)", tuple(violations), cols)
    return Evidence(name, PASS, f"all {lands} landing(s) of {len(ok)} decisions are on a monitor-accepted "
                    "candidate with every candidate ranked before rejected", (), cols)


def check_perturbation_coverage(images: Any, required: Sequence[str], min_images: int) -> Evidence:
    """EL-R08 on campaign readouts: each required perturbation has >= ``min_images`` non-faulted images.

    A missing perturbation or too few images is insufficient evidence (not a failure of the system).
    """
    name = "perturbation coverage"
    ok = _ok_images(images)
    rows = []
    for p in required:
        if ok is None or len(ok) == 0:
            n, sev = 0, ""
        else:
            sub = ok[ok["perturbation"] == p]
            n = int(sub["key"].nunique())
            sev = ", ".join(str(int(s)) for s in sorted(sub["severity"].unique()))
        faults = 0 if images is None or len(images) == 0 else int(
            ((images["perturbation"] == p) & (images["fault"].fillna("") != "")).sum())
        rows.append({"perturbation": p, "severities": sev or "-", "images": n, "faulted": faults,
                     "enough": n >= min_images})
    cols = ("perturbation", "severities", "images", "faulted", "enough")
    short = [f"{r['perturbation']} {_fewer(r['images'], min_images, 'evaluated images')}" if r["images"]
             else f"{r['perturbation']} not evaluated" for r in rows if not r["enough"]]
    if short:
        return Evidence(name, INSUFFICIENT, f"insufficient evidence: {'; '.join(short)}", tuple(rows), cols)
    return Evidence(name, PASS, f"all {len(required)} perturbations evaluated with >= {min_images} images each",
                    tuple(rows), cols)


def _fewer(n: int, needed: int, what: str) -> str:
    """``8 evaluated images, fewer than the 10 needed`` (a message's count against its minimum)."""
    return f"with {n} {what}, fewer than the {needed} needed"


def _deployed_rows(table: Any, monitor: str) -> Any:
    if table is None or len(table) == 0:
        return table
    return table[table["monitor"] == monitor]


def _finite(v: Any) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def check_safety_gain(table: Any, monitor: str, required: Sequence[str], min_images: int) -> Evidence:
    """EL-R09: G* 95% lower bound > 0 for ``monitor`` in every evaluated scenario.

    Insufficient when the monitor was not evaluated, a required perturbation is missing or has fewer
    than ``min_images`` images, or a lower bound is undefined.
    """
    name = f"safety gain G* of the deployed monitor ({monitor})"
    rows_df = _deployed_rows(table, monitor)
    cols = ("perturbation", "severity", "images", "g_star", "g_star_lo95", "g_star_hi95", "verdict")
    if rows_df is None or len(rows_df) == 0:
        return Evidence(name, INSUFFICIENT, f"insufficient evidence: monitor {monitor!r} was not evaluated")
    rows, fails, short = [], [], []
    for r in rows_df.itertuples(index=False):
        lo = r.g_star_lo95
        if int(r.images) < min_images or not _finite(lo):
            verdict = "insufficient"
            short.append(f"{r.perturbation} (s{int(r.severity)}) " + (
                _fewer(int(r.images), min_images, "images") if int(r.images) < min_images
                else "has no G* interval (its bootstrap is undefined)"))
        elif float(lo) > 0:
            verdict = "pass"
        else:
            verdict = "fail"
            fails.append(f"{r.perturbation} (s{int(r.severity)})")
        rows.append({"perturbation": r.perturbation, "severity": int(r.severity), "images": int(r.images),
                     "g_star": _num(r.g_star), "g_star_lo95": _num(lo), "g_star_hi95": _num(r.g_star_hi95),
                     "verdict": verdict})
    missing = [p for p in required if p not in set(rows_df["perturbation"])]
    if fails:
        return Evidence(name, FAIL, f"G* 95% lower bound <= 0 under {', '.join(fails)}", tuple(rows), cols)
    if missing or short:
        what = [f"{p} not evaluated" for p in missing] + short
        return Evidence(name, INSUFFICIENT, "insufficient evidence: " + "; ".join(what), tuple(rows), cols)
    return Evidence(name, PASS, f"G* 95% lower bound > 0 in all {len(rows)} scenario(s)", tuple(rows), cols)


def images_needed(bound: float, conf: float = 0.95) -> int:
    """The fewest images for which zero unsafe landings give a one-sided upper bound <= ``bound``.

    >>> images_needed(0.05)
    59
    """
    if not 0 < bound < 1:
        raise ValueError(f"bound must lie in (0, 1), got {bound!r}")
    # Clopper-Pearson with k = 0: ub = 1 - (1 - conf) ** (1 / n)  <=  bound
    return int(math.ceil(math.log(1.0 - conf) / math.log(1.0 - bound) - 1e-12))


def _images_needed_text(rate: float, bound: float, conf: float) -> str:
    n = images_needed_at(rate, bound, conf)
    return "none at this rate" if n is None else str(n)


def images_needed_at(rate: float, bound: float, conf: float = 0.95, limit: int = 10**6) -> int | None:
    """The fewest images at which an observed unsafe-landing rate of ``rate`` would show ``bound`` (one-sided
    Clopper-Pearson upper bound <= ``bound``); None when no sample can (``rate >= bound``, or past ``limit``).

    >>> images_needed_at(0.0, 0.05), images_needed_at(0.06, 0.05)
    (59, None)
    """
    if not 0 <= rate < bound:
        return None

    def shows(n: int) -> bool:
        return clopper_pearson_upper(int(math.floor(rate * n + 1e-9)), n, conf) <= bound

    hi = images_needed(bound, conf)
    while not shows(hi):
        hi *= 2
        if hi > limit:
            return None
    lo = 1
    while lo < hi:  # the smallest n that shows it (the bound falls with n at a fixed rate, floors aside)
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if shows(mid) else (mid + 1, hi)
    return hi


def _k_of(rate: Any, n: int) -> int:
    """The unsafe landings behind a table's rate over ``n`` images (0 when there are none or no rate)."""
    return int(round(float(rate) * n)) if n and _finite(rate) else 0


def confidence_text(conf: float) -> str:
    """A confidence level as the checks and the report show it (``0.95`` -> ``95%``, ``0.975`` -> ``97.5%``)."""
    return f"{float(conf) * 100:.10g}%"


def _bound_verdict(k: int, n: int, bound: float, conf: float) -> tuple[str, Any]:
    """One scenario of EL-R10: ("pass" | "fail" | "insufficient", the ``decide_rate_bound`` decision).

    Failed at any size when the lower bound exceeds ``bound``; in between, failed when the sample was large enough
    for zero unsafe landings to show ``bound`` (the acceptance criterion could be met and was not), else undecided.
    """
    d = decide_rate_bound(k, n, bound, conf)
    if d.verdict == BOUND_MET:
        return PASS, d
    if d.verdict == BOUND_MISSED or (n and clopper_pearson_upper(0, n, conf) <= bound):
        return FAIL, d
    return INSUFFICIENT, d


def check_unsafe_landing_bound(table: Any, monitor: str, bound: float, required: Sequence[str],
                               conf: float = 0.95) -> Evidence:
    """EL-R10: the unsafe-landing rate's one-sided ``conf`` upper bound <= ``bound`` for ``monitor``, per scenario.

    The bounds are computed here, at ``conf``, from each scenario's images and unsafe landings (exact
    Clopper-Pearson, ``decide_rate_bound``), never read from the table's fixed 95% column. A scenario fails at any
    sample size when its one-sided lower bound exceeds ``bound`` (the data already show the bound missed), and
    when its upper bound exceeds ``bound`` on a sample large enough for zero unsafe landings to meet it; only a
    smaller sample whose bounds straddle ``bound`` is too small to decide (insufficient).
    """
    level = confidence_text(conf)
    name = f"unsafe-landing rate of the deployed monitor ({monitor}), bound {bound:g} at {level} confidence"
    rows_df = _deployed_rows(table, monitor)
    cols = ("perturbation", "severity", "images", "unsafe_landings", "unsafe_landing_rate", "confidence",
            "lower_bound", "upper_bound", "over_bound_by", "images_needed", "verdict")
    if rows_df is None or len(rows_df) == 0:
        return Evidence(name, INSUFFICIENT, f"insufficient evidence: monitor {monitor!r} was not evaluated")
    need = images_needed(bound, conf)
    rows, shown_above, over, short = [], [], [], []
    for r in rows_df.itertuples(index=False):
        n = int(r.images)
        k = _k_of(r.unsafe_landing_rate, n)
        scen = f"{r.perturbation} (s{int(r.severity)})"
        if n == 0 or not _finite(r.unsafe_landing_rate):
            verdict, lb, ub = INSUFFICIENT, math.nan, math.nan
        else:
            verdict, d = _bound_verdict(k, n, bound, conf)
            lb, ub = d.lower, d.upper
        if verdict == INSUFFICIENT:
            short.append(scen)
        elif verdict == FAIL and lb > bound:
            shown_above.append(f"{scen}: {k} of {n}, lower bound {lb:.3f}")
        elif verdict == FAIL:
            over.append(f"{scen}: {k} of {n}, upper bound {ub:.3f}")
        rows.append({"perturbation": r.perturbation, "severity": int(r.severity), "images": n,
                     "unsafe_landings": k, "unsafe_landing_rate": _num(r.unsafe_landing_rate), "confidence": level,
                     "lower_bound": _num(lb), "upper_bound": _num(ub),
                     "over_bound_by": _num(ub - bound) if math.isfinite(ub) and ub > bound else 0.0,
                     "images_needed": _images_needed_text(k / n if n else 0.0, bound, conf), "verdict": verdict})
    missing = [p for p in required if p not in set(rows_df["perturbation"])]
    if shown_above or over:
        what = ([f"one-sided {level} lower bound > {bound:g} (the bound is missed at any sample size) under "
                 + "; ".join(shown_above)] if shown_above else [])
        what += ([f"one-sided {level} upper bound > {bound:g} under " + "; ".join(over)
                  + f" (>= {need} images: enough to show the bound)"] if over else [])
        return Evidence(name, FAIL, "; ".join(what) + "\n" + IMAGES_NEEDED_LEGEND, tuple(rows), cols)
    if missing or short:
        what = [f"{p} not evaluated" for p in missing]
        if short:
            what.append(f"{', '.join(short)}: too few images to show {bound:g} at {level} confidence (needs >= "
                        f"{need} images with no unsafe landing)")
        return Evidence(name, INSUFFICIENT, "insufficient evidence: " + "; ".join(what), tuple(rows), cols)
    return Evidence(name, PASS, f"one-sided {level} upper bound <= {bound:g} in all {len(rows)} scenario(s)",
                    tuple(rows), cols)


IMAGES_NEEDED_LEGEND = "(column images_needed: the images at which the observed rate would show the bound)"
"""The legend of the bound's ``images_needed`` column: a line of its own after the verdict."""


def check_decision_time(images: Any, monitor: str, budget_s: float) -> Evidence:
    """EL-R13: every image's decision time with ``monitor`` (segmentation + candidates + the walk's
    monitoring overhead) is within ``budget_s`` on the campaign's machine."""
    name = f"decision time of the deployed monitor ({monitor}) within {budget_s:g} s"
    ok = _ok_images(images)
    cols = ("perturbation", "severity", "images", "mean_s", "p95_s", "max_s", "over_budget")
    if ok is None or len(ok) == 0 or not (ok["monitor"] == monitor).any():
        return Evidence(name, INSUFFICIENT, f"insufficient evidence: monitor {monitor!r} was not evaluated")
    sub = ok[ok["monitor"] == monitor]
    t = (sub["segmentation_s"].astype(float) + sub["candidates_s"].astype(float) + sub["overhead_s"].astype(float))
    sub = sub.assign(decision_s=t)
    rows = []
    for (p, s), g in sub.groupby(["perturbation", "severity"], sort=False):
        d = g["decision_s"].to_numpy(float)
        rows.append({"perturbation": p, "severity": int(s), "images": len(d), "mean_s": _num(d.mean()),
                     "p95_s": _num(np.percentile(d, 95)), "max_s": _num(d.max()),
                     "over_budget": int((d > budget_s).sum())})
    over = int((t > budget_s).sum())
    if over:
        return Evidence(name, FAIL, f"{over} of {len(t)} decisions took longer than {budget_s:g} s "
                        f"(max {t.max():.2f} s)", tuple(rows), cols)
    return Evidence(name, PASS, f"all {len(t)} decisions within {budget_s:g} s (max {t.max():.2f} s)",
                    tuple(rows), cols)


def pose_margin(core: Any, size: tuple[int, int], pose_error: Mapping[str, float]) -> tuple[dict[str, Any], float]:
    """The pose-error margin at working resolution: (a row with beta and the required beta rounded, the required
    beta) for the pose-error box.

    ``core``: a CoreConfig or its dict (``CoreConfig.to_dict``); ``size``: the input image (W, H).
    """
    cfg = core if isinstance(core, CoreConfig) else CoreConfig.from_dict(dict(core))
    w, h = working_size(int(size[0]), int(size[1]), cfg.working_width)
    geo = cfg.geometry(w, h)  # with the core's reach_m: beta is judged over the rows it plans on
    he, pe = float(pose_error["height"]), float(pose_error["pitch"])
    need = required_beta(geo, height_error=he, pitch_error=pe)
    return {"working_size": f"{w}x{h}", "height_m": cfg.pose.height_m, "pitch_deg": cfg.pose.pitch_deg,
            "height_error": he, "pitch_error": pe, "radius_m": float(cfg.safety.radius_m),
            "beta": float(cfg.safety.beta), "required_beta": round(need, 4)}, need


def check_pose_margin(core: Any, size: tuple[int, int], pose_error: Mapping[str, float],
                      safety: Mapping[str, float] | None = None) -> Evidence:
    """EL-R14: beta >= the beta required for the pose-error box, at working resolution (``pose_margin``).

    ``safety``: the declared targets ``{"radius_m": R, "beta": beta}`` (the registry's parameters); a
    configuration planned with another R or beta does not judge them (insufficient, naming both).
    """
    row, need = pose_margin(core, size, pose_error)
    if safety is not None:
        want_r, want_b = float(safety["radius_m"]), float(safety["beta"])
        if not (math.isclose(row["radius_m"], want_r) and math.isclose(row["beta"], want_b)):
            return Evidence("pose-error margin of beta", INSUFFICIENT,
                            f"insufficient evidence: the campaign planned with R = {row['radius_m']:g} m, beta = "
                            f"{row['beta']:g}; the targets declare R = {want_r:g} m, beta = {want_b:g}",
                            (row,), tuple(row))
    beta, he, pe = row["beta"], row["height_error"], row["pitch_error"]
    rel = ">=" if beta >= need else "<"
    verdict = f"beta {beta:g} {rel} required {need:.3f} for +-{he:.0%} height, +-{pe:.0%} pitch"
    return Evidence("pose-error margin of beta", PASS if beta >= need else FAIL, verdict, (row,), tuple(row))


def own_poses(images: Any) -> list[tuple[float, float]]:
    """The distinct (height_m, pitch_deg) of the frames a run planned at their own pose (``pose_source`` not
    nominal), from its images readouts; empty for a run at the nominal pose."""
    if images is None or not {"height_m", "pitch_deg", "pose_source"} <= set(images.columns):
        return []
    framed = images[(images["pose_source"] != "nominal") & images["height_m"].notna()]
    return sorted(set(zip(framed["height_m"], framed["pitch_deg"], strict=True)))


def _pose_configs(core: Any, poses: Any) -> list[dict[str, Any]]:
    """The core configuration (a CoreConfig or its dict) at the nominal pose, then at each of ``poses``."""
    base = dict(core) if isinstance(core, Mapping) else core.to_dict()
    return [base, *({**base, "pose": {"height_m": float(h), "pitch_deg": float(p)}} for h, p in poses)]


def worst_required_beta(core: Any, size: tuple[int, int], poses: Any, pose_error: Mapping[str, float]) -> float:
    """The largest beta the pose-error box requires over the nominal pose and each of ``poses`` (what EL-R14,
    :func:`check_pose_margins`, compares beta with)."""
    return max(pose_margin(c, size, pose_error)[1] for c in _pose_configs(core, poses))


def check_pose_margins(core: Any, size: tuple[int, int], poses: Any, pose_error: Mapping[str, float],
                       safety: Mapping[str, float] | None = None) -> Evidence:
    """EL-R14 over every pose a run planned at: the nominal one and each frame's own (``poses``: distinct
    (height_m, pitch_deg) pairs from the images readouts); fails when beta falls short at any of them."""
    evidences = [check_pose_margin(c, size, pose_error, safety) for c in _pose_configs(core, poses)]
    rows = tuple(r for ev in evidences for r in ev.rows)
    rank = {FAIL: 0, INSUFFICIENT: 1, PASS: 2}
    worst = min(evidences, key=lambda ev: (rank.get(ev.status, 1),
                                           -max((r.get("required_beta", 0.0) for r in ev.rows), default=0.0)))
    if len(evidences) == 1:
        return worst
    summary = f"{worst.summary} (worst of {len(evidences)} poses: the nominal one and each frame's own)"
    return Evidence(worst.name, worst.status, summary, rows, evidences[0].columns)


def _sha(v: Any) -> bool:
    return isinstance(v, str) and re.fullmatch(r"[0-9a-f]{64}", v) is not None


def check_artefacts_identified(manifest: Mapping[str, Any]) -> Evidence:
    """EL-R12 on a run: its manifest identifies weights and data by SHA-256, and the code by its git commit (run
    from the toolkit's own checkout) or by its version and the SHA-256 of its package files (an installed
    package)."""
    code = manifest.get("code") or {}
    by_files = bool(code.get("version")) and _sha(code.get("sha256"))
    rows = [
        {"artefact": "weights", "identity": (manifest.get("weights") or {}).get("sha256")},
        {"artefact": "data", "identity": (manifest.get("data") or {}).get("sha256")},
        {"artefact": "configuration", "identity": config_sha256(manifest.get("config") or {})
         if manifest.get("config") else None},
        {"artefact": "code", "identity": code.get("git_commit") or (
            f"{code['version']} (package files {code['sha256']})" if by_files else None)},
    ]
    bad = [r["artefact"] for r in rows[:3] if not _sha(r["identity"])]
    if not rows[3]["identity"]:
        bad.append("code (neither a git commit nor a version with the hash of its files)")
    cols = ("artefact", "identity")
    if bad:
        return Evidence("artefacts identified by the run manifest", FAIL,
                        f"the run manifest does not identify: {', '.join(bad)}", tuple(rows), cols)
    how = "git commit" if code.get("git_commit") else "version and SHA-256 of its package files"
    return Evidence("artefacts identified by the run manifest", PASS,
                    f"weights, data and configuration identified by SHA-256, code by {how}", tuple(rows), cols)


def config_sha256(config: Mapping[str, Any]) -> str:
    """SHA-256 of a configuration as canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
