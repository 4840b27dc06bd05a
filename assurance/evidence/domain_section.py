"""The report's declared operating domain (the run's ``[odd]``, ``el.geometry.odd``): per dimension the declaration and
the evidence that covers it (campaign frames, the pose margin of beta, the perturbations and severities
evaluated), and per perturbation the frames that ended outside the domain."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from assurance.campaign.perturbation_plan import outside_scenarios
from el.geometry.odd import OUTSIDE_ODD, OperatingDomain


def _span(values: Any, unit: str) -> str:
    lo, hi = float(values.min()), float(values.max())
    return f"{lo:g}{unit}" if lo == hi else f"{lo:g} to {hi:g}{unit}"


def _within(values: Any, lo: float, hi: float) -> int:
    return int(((values >= lo) & (values <= hi)).sum())


PHYSICAL = {"height_m": (0.0, None), "pitch_deg": (0.0, 90.0)}
"""The physical range of a pose dimension (a pitch is at most 90 degrees below the horizon: straight down)."""


def _margin(frames: Any, col: str, nominal: float, error: float, unit: str, short: str) -> str:
    """What the pose-error margin of beta covers: ``error`` around the nominal pose, or around each frame's own
    pose when the frames were planned with their own (``pose_source``), clipped to the physical range; ``short``:
    why beta does not cover it (empty when it does)."""
    own = (frames[(frames["pose_source"].fillna("nominal") != "nominal") & frames[col].notna()]
           if frames is not None and "pose_source" in frames else None)
    floor, ceil = PHYSICAL[col]
    framed = own is not None and len(own) > 0
    lo, hi = (float(own[col].min()), float(own[col].max())) if framed else (nominal, nominal)
    around = "each frame's own pose" if framed else f"the nominal {nominal:g}{unit}"
    a, b = max(floor, lo * (1 - error)), hi * (1 + error)
    b = min(ceil, b) if ceil is not None else b
    span = f"{a:.3g} to {b:.3g}{unit}" + (" over the evaluated frames" if framed else "")
    if short:
        return f"; the pose-error margin of {error:.0%} around {around} ({span}) is NOT absorbed: {short}"
    return f"; the safety coefficient beta absorbs {error:.0%} around {around} (the pose-error margin), i.e. {span}"


def odd_rows(man: Mapping[str, Any], images: Any, pose_error: Mapping[str, float],
             need: float | None = None) -> list[dict[str, str]]:
    """One row per declared dimension (name, declared, evidence); empty when the run declares no domain. ``need``:
    the beta the pose-error box requires (``sections.required_beta``; None: not known), so that a row says beta
    absorbs the pose error only where it does."""
    record = man["config"].get("odd")
    if record is None:
        return []
    odd = OperatingDomain.from_dict(record)
    ok = images[images["fault"].fillna("") == ""] if len(images) else images
    frames = ok.drop_duplicates(["perturbation", "severity", "key"]) if len(ok) else ok
    n = len(frames)
    images_n = frames["key"].nunique() if n else 0
    scenarios_n = len(frames.drop_duplicates(["perturbation", "severity"])) if n else 0
    counted = (f" ({images_n} image{'s' if images_n != 1 else ''} x {scenarios_n} perturbation scenarios)"
               if scenarios_n > 1 else "")
    nominal = man["config"]["core"]["pose"]
    beta = ((man["config"]["core"].get("safety") or {}).get("beta"))
    short = ("the beta it needs is not known (no evaluated image)" if need is None or beta is None else
             f"beta = {float(beta):g} where {need:.3f} is required" if need > float(beta) else "")
    rows = []
    for name, col, (lo, hi), unit, err in (("Height", "height_m", odd.height_m, " m", "height"),
                                           ("Pitch", "pitch_deg", odd.pitch_deg, " deg", "pitch")):
        seen = (f"{n} evaluated frames{counted} at {_span(frames[col], unit)} ({_within(frames[col], lo, hi)} "
                "inside)" if n and col in frames else "no evaluated frame")
        margin = _margin(frames if n and col in frames else None, col, nominal[col], pose_error[err], unit, short)
        rows.append({"name": name, "declared": f"{lo:g} to {hi:g}{unit}", "evidence": seen + margin})
    sizes = (sorted({(int(w), int(h)) for w, h in zip(frames["width"], frames["height"], strict=True)})
             if n else [])
    shown = ", ".join(f"{w}x{h}" for w, h in sizes[:6]) + (" ..." if len(sizes) > 6 else "")
    fits = int((frames["width"].between(*odd.image_width) & frames["height"].between(*odd.image_height)).sum()) \
        if n else 0
    rows.append({"name": "Image size", "declared": f"width {odd.image_width[0]:g} to {odd.image_width[1]:g} px, "
                 f"height {odd.image_height[0]:g} to {odd.image_height[1]:g} px",
                 "evidence": f"frames evaluated at {shown} ({fits} of {n} inside; the network segments at its working "
                             "width)" if sizes else "no evaluated frame"})
    rows.append({"name": "Aspect", "declared": f"{odd.aspect[0]:g} to {odd.aspect[1]:g}",
                 "evidence": ", ".join(sorted({f"{w / h:.3f}" for w, h in sizes})) or "no evaluated frame"})
    evaluated = {(str(p), int(s)) for p, s in zip(frames["perturbation"], frames["severity"], strict=True)} \
        if n else set()
    refused = frames["reason"].astype(str).str.startswith(OUTSIDE_ODD) if n else None
    kept = frames[~refused] if n else frames
    judged = {(str(p), int(s)) for p, s in zip(kept["perturbation"], kept["severity"], strict=True)} if n else set()
    for pert, level in odd.perturbations.items():
        sev = sorted(s for p, s in evaluated if p == pert)
        state = ("covered" if (pert, level) in judged else
                 "NOT covered: every frame of it was refused outside the declared domain" if level in sev else
                 "NOT evaluated at the declared maximum")
        rows.append({"name": f"Perturbation {pert}", "declared": f"up to severity {level}",
                     "evidence": (f"evaluated at severit{'y' if len(sev) == 1 else 'ies'} {', '.join(map(str, sev))}: "
                                  f"{state}") if sev else "not evaluated by this run"})
    beyond = sorted({f"{p} {s}" for p, s in evaluated if not odd.covers(p, s)})
    if beyond:
        rows.append({"name": "Evaluated outside the domain", "declared": "not among the declared perturbations",
                     "evidence": ", ".join(beyond) + ": evaluated by the campaign, not covered by the declaration; "
                                 f"marked {OUTSIDE_MARK} in the results"})
    out = frames[refused] if n else frames
    per = out.groupby("perturbation")["key"].nunique().to_dict() if len(out) else {}
    rows.append({"name": "Frames outside", "declared": "default action, reason outside_odd",
                 "evidence": ", ".join(f"{p}: {per.get(p, 0)}" for p in dict.fromkeys(frames["perturbation"]))
                 if n else "no evaluated frame"})
    scored = frames[frames["frame_gate_score"].notna()] if n and "frame_gate_score" in frames else frames.iloc[:0]
    if len(scored):  # the run deployed a frame gate (el.monitors.frame_gate): the frames it refused
        gated = scored[scored["reason"].astype(str).str.startswith("out_of_domain: frame gate")]
        per = gated.groupby("perturbation")["key"].nunique().to_dict()
        rows.append({"name": "Frame gate", "declared": f"default action above score "
                     f"{float(scored['frame_gate_threshold'].iloc[0]):.4g}, reason out_of_domain",
                     "evidence": "frames refused: " + ", ".join(f"{p}: {per.get(p, 0)}"
                                                               for p in dict.fromkeys(scored["perturbation"]))})
    return rows


OUTSIDE_MARK = "(outside the declared domain)"


def mark_outside(view: dict[str, Any], table: Any, man: Mapping[str, Any]) -> dict[str, Any]:
    """The results view (``sections.results_view``: one row per ``table`` record, in order) with each scenario the
    run evaluated outside its declared domain marked (``assurance.campaign.perturbation_plan.outside_scenarios``)."""
    outside = outside_scenarios(man)
    if not outside or not len(table):
        return view
    for row, rec in zip(view["rows"], table.to_dict("records"), strict=True):
        if row["scenario"] and (str(rec["perturbation"]), int(rec["severity"])) in outside:
            row["scenario"] = f"{row['scenario']} {OUTSIDE_MARK}"
    return view


def frame_gate_view() -> dict[str, Any] | None:
    """The frame-gate measurement shipped with the package (``assurance/data/frame_gates.{csv,png}``, written by
    ``assurance.fitting.gate_study`` on validation scenes): per set the share each candidate gate flags ("-": not
    measured in that fold)."""
    import base64
    import csv
    from importlib import resources

    data = resources.files("assurance").joinpath("data")
    try:
        text = data.joinpath("frame_gates.csv").read_text(encoding="utf-8")
        png = data.joinpath("frame_gates.png").read_bytes()
    except OSError:
        return None
    rows = list(csv.DictReader(text.splitlines()))
    gates = [k for k in (rows[0] if rows else {}) if k not in ("set", "what", "frames")]
    shown = [{"set": r["set"] if r["set"] == r["what"] else f"{r['set']}: {r['what']}", "frames": r["frames"],
              "rates": [f"{float(r[g]):.0%}" if r[g] else "-" for g in gates]} for r in rows]
    return {"gates": gates, "rows": shown, "uri": "data:image/png;base64," + base64.b64encode(png).decode("ascii")}
