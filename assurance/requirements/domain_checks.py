"""EL-R17 on campaign readouts: a frame outside the declared operating domain (``el.geometry.odd``) never ends in a
landing; and, per perturbation, how many frames ended outside the domain (the release evidence's count)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from assurance.requirements.records import FAIL, INSUFFICIENT, PASS, Evidence
from el.geometry.camera import Pose
from el.geometry.odd import OUTSIDE_ODD, OperatingDomain

COLUMNS = ("perturbation", "severity", "declared", "frames", "outside", "landings_outside")
VIOLATION_COLUMNS = ("perturbation", "severity", "monitor", "image", "problem")


def check_outside_domain(images: Any, odd: Mapping[str, Any] | None) -> Evidence:
    """Every non-faulted decision of a frame whose pose and size (readout columns ``height_m``, ``pitch_deg``,
    ``width``, ``height``) are outside ``odd`` is the default action; the rows count, per perturbation and
    severity, the frames outside and whether the scenario is inside the declared perturbations."""
    name = "no landing outside the declared operating domain"
    if odd is None:
        return Evidence(name, INSUFFICIENT, "insufficient evidence: the run declares no operating domain "
                                            "(a campaign run before [odd] existed)")
    ok = None if images is None or len(images) == 0 else images[images["fault"].fillna("") == ""]
    if ok is None or len(ok) == 0 or not {"height_m", "pitch_deg"} <= set(ok.columns):
        return Evidence(name, INSUFFICIENT, "no evaluated image with its pose in the readouts")
    domain = OperatingDomain.from_dict(odd)
    violations: list[dict[str, Any]] = []
    counts: dict[tuple[str, int], dict[str, Any]] = {}
    for row in ok.itertuples(index=False):
        outside = domain.outside(Pose(height_m=float(row.height_m), pitch_deg=float(row.pitch_deg)),
                                 (int(row.width), int(row.height)))
        key = (str(row.perturbation), int(row.severity))
        c = counts.setdefault(key, {"perturbation": key[0], "severity": key[1],
                                    "declared": "yes" if domain.covers(*key) else "no", "frames": set(),
                                    "outside": set(), "landings_outside": 0})
        c["frames"].add(row.key)
        refused = str(row.reason).startswith(OUTSIDE_ODD)
        if outside or refused:
            c["outside"].add(row.key)
        if (outside or refused) and row.action == "land":
            c["landings_outside"] += 1
            violations.append({"perturbation": key[0], "severity": key[1], "monitor": row.monitor,
                               "image": row.key, "problem": f"landed although {outside or row.reason}"})
    rows = tuple({**c, "frames": len(c["frames"]), "outside": len(c["outside"])} for c in counts.values())
    outside_total = sum(r["outside"] for r in rows)
    if violations:
        return Evidence(name, FAIL, f"{len(violations)} landing(s) on frames outside the declared domain",
                        tuple(violations), VIOLATION_COLUMNS)
    return Evidence(name, PASS, f"{outside_total} frame(s) of {sum(r['frames'] for r in rows)} outside the declared "
                    "domain, none landed", rows, COLUMNS)
