"""What the requirement texts and the declared operating domain say about the system assessed.

The registry's texts are written once for every system: where they name the platform, the camera, the pose, the
ground rule, the scenes, the conditions or the forbidden classes they use a placeholder (``{platform}``,
``{camera}``, ``{pose}``, ``{ground}``, ``{scenes}``, ``{conditions}``, ``{forbidden}``) filled from these facts.
``facts_of`` derives them from a built system (its camera, nominal pose, declared domain and its perturbations,
pose policy and label set), so a report about another system says nothing of the shipped one;
``shipped_facts`` are the embedded default's (what a registry loaded without a system reads).

A fact is literal text, never a template: a camera named ``Cam {A}`` or a class named ``{confidence:pct} x`` is
shown as written (formatting it would fail blaming the packaged registry, or print "95% x"). The one exception is
the toolkit's own wording of :data:`TEMPLATE_FACTS` (the pose's errors are the registry's parameters), which holds
numbers and fixed words only, user text escaped (:func:`escape`).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

from assurance.system.system import System
from el.base.decision import DEFAULT_AREA_BASES
from el.classes.labels import UAVID
from el.geometry.camera import PHANTOM4, Pose
from el.geometry.config import CoreConfig
from el.landing.core import default_area

FACT_KEYS = ("platform", "camera", "view", "pose", "ground", "scenes", "conditions", "forbidden", "safe", "label_set")
TEMPLATE_FACTS = ("pose",)
"""Facts whose text holds the registry's placeholders (``{pose_error.height:pct}``), rendered with its parameters;
every other fact is substituted as literal text."""


def escape(text: str) -> str:
    """``text`` as literal text inside a template of :data:`TEMPLATE_FACTS` (braces doubled)."""
    return text.replace("{", "{{").replace("}", "}}")
NADIR_PITCH_DEG = 80.0  # a nominal pitch at or beyond this looks (almost) straight down: a nadir view


def _names(names: Sequence[str], conj: str = "or") -> str:
    """``a, b or c`` with class names as words (``static_car`` -> ``static car``)."""
    words = [n.replace("_", " ") for n in names]
    if len(words) <= 1:
        return "".join(words)
    return f"{', '.join(words[:-1])} {conj} {words[-1]}"


def view_of(pitch_deg: float) -> str:
    """``nadir view`` (looking straight down) or ``oblique view``, from the nominal pitch."""
    return "nadir view (looking straight down)" if pitch_deg >= NADIR_PITCH_DEG else "oblique view"


def camera_text(intrinsics: Any, pitch_deg: float, *, named: bool = True) -> str:
    """The camera as the operating domain names it: name (``named``: declared; else said to be undeclared), sensor,
    lens, field of view and view."""
    who = f"camera '{intrinsics.name}'" if named else "a camera of no declared name"
    return (f"{who} ({intrinsics.sensor_width_mm:g} mm sensor width, {intrinsics.focal_mm:.3g} "
            f"mm focal length, {intrinsics.hfov_deg:.1f} degrees horizontal field of view), {view_of(pitch_deg)}")


SHIPPED_PLATFORM = "small multirotor UAV with a parachute, over urban areas"
"""The shipped system's platform and the area it flies over (the paper's urban setting)."""
PLATFORM = ("not declared (the system file has no key for it); the method assumes a small multirotor UAV whose "
            "default action is a descent under a parachute; the area flown over is not declared either: see the "
            "scenes")
"""Another system's platform: the toolkit's assumption only, no area said of it."""

SHIPPED_CONDITIONS = ("daylight; the six perturbations of ICRA22 at severity 3 (brightness, fog, motion blur, "
                      "shifted pixels, pixel trap, none)")
"""The shipped system's conditions (the paper's protocol, which its release run follows)."""


def conditions_text(file: Any, odd: Any) -> str:
    """The conditions a system's evidence is declared for: the perturbations and maximum severities of its
    ``[odd]`` (the embedded default's when its file declares none, and said so; a maximum of 0 declares nothing),
    and the unperturbed frames."""
    levels = {n: s for n, s in dict(getattr(odd, "perturbations", None) or {}).items() if s > 0}
    listed = ", ".join(f"{n.replace('_', ' ')} up to severity {s}" for n, s in levels.items())
    source = ("as declared in [odd] perturbations of its system file" if file.declares_perturbations else
              "its system file declares none: the embedded default's [odd] perturbations")
    return f"the unperturbed frames and {listed} ({source})" if listed else f"the unperturbed frames only ({source})"


def _range(values: Any, unit: str) -> str | None:
    if not values:
        return None
    lo, hi = values
    return f"{lo:g} to {hi:g}{unit}"


def pose_text(pose: Any, odd: Any, policy: str) -> str:
    """The nominal pose, the declared ranges and where each frame's pose comes from."""
    ranges = [r for r in (_range(getattr(odd, "height_m", None), " m height"),
                          _range(getattr(odd, "pitch_deg", None), " degrees pitch")) if r]
    source = {"nominal": "every frame planned with the nominal pose",
              "sidecar": "each frame's own pose from the flight log where it has one, else the nominal pose",
              "required": "each frame's own pose from the flight log (a frame without one takes the default "
                          "action)"}.get(policy, f"pose policy {escape(repr(policy))}")
    declared = f"; declared domain {', '.join(ranges)}" if ranges else ""
    return (f"height {pose.height_m:g} m, pitch {pose.pitch_deg:g} degrees below the horizon (nominal){declared}; "
            f"{source}; errors up to {{pose_error.height:pct}} in height and {{pose_error.pitch:pct}} in pitch")


def forbidden_text(labels: Any) -> str:
    """The label set's forbidden classes by name, as a requirement text reads them (``road, building or car``)."""
    return _names([labels.names[i] for i in labels.forbidden_ids])


def facts_of(system: Any) -> dict[str, str]:
    """The facts of a built ``assurance.system.System`` (its camera, pose, declared domain, label set)."""
    core, labels = system.core, system.labels
    pose = core.pose
    name = getattr(system.file, "name", None) or system.label
    data = "the system's own data sets ([data] of its system file)"
    shipped = bool(system.file.default)
    return {
        "platform": SHIPPED_PLATFORM if shipped else PLATFORM,
        "camera": camera_text(core.intrinsics, pose.pitch_deg, named=system.file.camera_named()),
        "view": view_of(pose.pitch_deg),
        "pose": pose_text(pose, system.odd, system.poses),
        "ground": ground_text(system),
        "scenes": f"the scenes of {name}: {data}" if not shipped else SHIPPED_SCENES,
        "conditions": SHIPPED_CONDITIONS if shipped else conditions_text(system.file, system.odd),
        "forbidden": forbidden_text(labels),
        "safe": _names([labels.names[i] for i in labels.safe_ids], "and"),
        "label_set": labels.name,
    }


SHIPPED_SCENES = ("urban scenes with roads, buildings, parked and moving cars, trees, low vegetation, people and "
                  "clutter; in this toolkit synthetic scenes in the UAVid layout (UAVid itself when a user has it)")


def ground_text(system: Any) -> str:
    """The ground model and where the default action lands at the system's nominal pose and image size."""
    return _ground(*system.file.image_size(), system.core)


def _ground(width: int, height: int, core: Any) -> str:
    area = default_area(width, height, core)
    where = DEFAULT_AREA_BASES.get(getattr(area, "basis", None) or "", "the bottom centre of the frame")
    at = f"at ({area.x:.0f}, {area.y:.0f}) px of a {width}x{height} frame at the nominal pose"
    return f"flat ground plane (pinhole geometry); the default action's landing area is {where}, {at}"


def facts_of_file(file: Any) -> dict[str, str]:
    """The facts of a system file (``assurance.system.SystemFile``): the system built from it, as :func:`facts_of`;
    the embedded default's are :func:`shipped_facts`."""
    if file is None or getattr(file, "default", False):
        return dict(shipped_facts())

    return facts_of(System.build(file))


@functools.cache
def shipped_facts() -> dict[str, str]:
    """The embedded default system's facts (the shipped camera, pose and UAVid classes), without building it;
    computed once (every registry load renders its texts from them). Callers copy before changing them."""
    pose = Pose()
    return {
        "platform": SHIPPED_PLATFORM,
        "camera": camera_text(PHANTOM4, pose.pitch_deg),
        "view": view_of(pose.pitch_deg),
        "pose": (f"height {pose.height_m:g} m, pitch {pose.pitch_deg:g} degrees below the horizon (nominal), errors up "
                 "to {pose_error.height:pct} in height and {pose_error.pitch:pct} in pitch"),
        "ground": _ground(3840, 2160, CoreConfig()),
        "scenes": SHIPPED_SCENES,
        "conditions": SHIPPED_CONDITIONS,
        "forbidden": forbidden_text(UAVID),
        "safe": _names([UAVID.names[i] for i in UAVID.safe_ids], "and"),
        "label_set": UAVID.name,
    }


def check_facts(facts: dict[str, str]) -> dict[str, str]:
    """The facts with every key present and every value a finite, non-empty string (the placeholders of a
    :data:`TEMPLATE_FACTS` fact, such as ``{pose_error.height:pct}``, are rendered with the registry's parameters
    afterwards; every other fact is literal text)."""
    missing = [k for k in FACT_KEYS if not isinstance(facts.get(k), str) or not facts[k].strip()]
    if missing:
        raise ValueError(f"system facts missing: {', '.join(missing)}")
    return {k: facts[k] for k in FACT_KEYS}


__all__ = ["FACT_KEYS", "PLATFORM", "SHIPPED_CONDITIONS", "SHIPPED_PLATFORM", "TEMPLATE_FACTS", "camera_text",
           "check_facts", "conditions_text", "escape", "facts_of", "facts_of_file", "forbidden_text", "pose_text",
           "shipped_facts", "view_of"]
