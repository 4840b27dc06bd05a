"""What the evidence report states about the system assessed, as one record (:class:`ReportFacts`) built once per
report (:func:`report_facts`) from the system file (the user's, the run's own as its signed manifest records it, or
the embedded default) and the run's signed manifest and per-frame readouts.

Every sentence of the report about the system takes its facts from here: the registry's texts (camera, pose,
ground, scenes, conditions, forbidden classes: ``assurance.requirements.system_facts``), the camera as evaluated and
whether its name was declared, which image stripes may hold a landing, where each frame's pose came from, the
data's provenance and licence as declared (``"not declared"`` otherwise: never guessed; the development data the
file declares is the data record's, ``assurance.evidence.records``), the frame gate as its file says, the waiver
file, and the release run's size (the shipped system's only). A literal about the shipped system is never said of
another.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from assurance.campaign.presets import preset_config
from assurance.dataio.layouts import data_source, resolve
from assurance.dataio.poses import POSES_FILE
from assurance.evidence.render import rel
from assurance.requirements.system_facts import facts_of_file
from assurance.system import default_system
from el.base.hashing import sha256_file
from el.base.records import body_sha256, record_body
from el.geometry.camera import MIN_DEPRESSION_DEG, NUM_STRIPES, Pose
from el.geometry.config import CoreConfig
from el.monitors.gates.features import WHAT

NOT_DECLARED = "not declared"
POLICIES = {"nominal": "the nominal pose for every frame", "sidecar": "each frame's own pose where it has one, else "
            "the nominal pose", "required": "each frame's own pose (a frame without one is a fault of its task)"}
"""The campaign's pose policy (``assurance.dataio.poses.POLICIES``) in words."""
SOURCES = {"frame": "its own pose from {poses}", "meta": "the pose its scene meta records",
           "nominal": "the nominal pose"}
"""Where a frame's pose came from (the ``pose_source`` readout) in words; ``{poses}``: the file (:func:`poses_file`)."""
SEQUENCE_POSES = "its sequence's poses.csv"
"""Where a UAVid split's frames take their own poses from (a sidecar per sequence)."""


@dataclass(frozen=True)
class ReportFacts:
    """The report's facts about the system assessed (see the module docstring)."""

    shipped: bool
    system: str
    texts: Mapping[str, str]
    camera: str
    stripes: str
    pose_source: str
    frame_gate: str
    waivers: str
    release_images: int | None = None
    data_provenance: str | None = None
    data_licence: str | None = None
    data_folders: tuple[Path, ...] = ()
    trained_by: str | None = None
    model_licence: str | None = None
    own_poses: Mapping[str, tuple[float, float]] | None = None  # height_m, pitch_deg: min and max of own poses
    poses_from: str = ""  # where the frames' own poses came from (poses_file)

    def view(self) -> dict[str, Any]:
        """The facts as the templates read them (``facts.camera``, ``facts.forbidden``, ``facts.stripes``, ...)."""
        return {**self.texts, "shipped": self.shipped, "system": self.system, "camera_evaluated": self.camera,
                "stripes": self.stripes, "pose_source": self.pose_source, "frame_gate": self.frame_gate,
                "waivers": self.waivers, "release_images": self.release_images,
                "data_provenance": self.data_provenance or NOT_DECLARED,
                "data_licence": self.data_licence or NOT_DECLARED}

    def declared_for(self, folder: str | Path | None) -> tuple[str | None, str | None]:
        """The provenance and licence the system file declares for one of its ``[data]`` folders (``[data]
        provenance``, ``[data] licence``; None each where it declares none); (None, None) for another folder."""
        if not folder or _resolved(folder) not in self.data_folders:
            return None, None
        return self.data_provenance, self.data_licence


def _resolved(path: str | Path) -> Path:
    return Path(path).expanduser().resolve()


def _data_folders(file: Any) -> tuple[Path, ...]:
    """The folders of the file's ``[data]`` splits, resolved against its folder (a split given as a table: its
    ``path``)."""
    out = []
    for split in ("train", "val", "test"):
        value = file.get(f"data.{split}")
        if isinstance(value, Mapping):
            value = value.get("path")
        if isinstance(value, str) and value:
            p = Path(value).expanduser()
            out.append(_resolved(p if p.is_absolute() else Path(file.base) / p))
    return tuple(out)


def _ok_frames(images: Any) -> Any:
    """The evaluated frames without a fault, one row per frame (perturbations share a frame's pose and size)."""
    if images is None or not len(images):
        return None
    ok = images[images["fault"].fillna("") == ""]
    return ok.drop_duplicates("key") if len(ok) else None


def camera_row(core: Mapping[str, Any], named: bool) -> str:
    """The camera as the run evaluated it (its manifest's intrinsics), saying when its name was not declared."""
    intr = core["intrinsics"]
    note = "" if named else " (name not declared in the system file)"
    return (f"{intr.get('name', '?')}{note}: sensor width {intr['sensor_width_mm']:g} mm, focal length "
            f"{intr['focal_mm']:.3g} mm, pinhole, square pixels")


def stripes_text(core: Mapping[str, Any], frames: Any, size: tuple[int, int] | None) -> str:
    """Which image stripes may hold a landing (``el.geometry.camera.CameraGeometry.unreachable_stripes``) at the poses
    and
    sizes of the evaluated frames (else the nominal pose at ``size``)."""
    try:
        cfg = CoreConfig.from_dict(dict(core))
        cases = {(int(w), int(h), float(a), float(p)) for w, h, a, p in zip(
            frames["width"], frames["height"], frames["height_m"], frames["pitch_deg"], strict=True)} \
            if frames is not None and {"width", "height", "height_m", "pitch_deg"} <= set(frames.columns) else set()
        if not cases and size is not None:
            cases = {(size[0], size[1], cfg.pose.height_m, cfg.pose.pitch_deg)}
        counts = sorted({replace(cfg, pose=Pose(height_m=a, pitch_deg=p)).geometry(w, h).unreachable_stripes
                         for w, h, a, p in cases})
    except (TypeError, ValueError, KeyError) as exc:
        return f"not computed ({exc})"
    if not counts:
        return "not computed (no evaluated frame)"
    poses = "at the nominal pose" if len(cases) == 1 else f"over the {len(cases)} poses and sizes of the frames"
    why = (f"(el.geometry.camera.CameraGeometry {poses}: a stripe is a landing target when its top row looks at least "
           f"{MIN_DEPRESSION_DEG:g} degrees below the horizon and sees ground within {cfg.reach_m:g} m)")
    if counts == [0]:
        return f"all {NUM_STRIPES} image stripes reachable, none excluded {why}"
    shown = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]} to {counts[-1]}"
    return f"top {shown} of {NUM_STRIPES} image stripes never reachable {why}"


def poses_file(data: Mapping[str, Any] | None) -> str:
    """Where the run's frames took their own poses from (``assurance.dataio.layouts``): the ``poses`` file its
    ``[data]`` table names, a flat layout's ``ROOT/poses.csv``, or a UAVid split's per-sequence ``poses.csv``."""
    data = data or {}
    spec = data.get("spec") or {}
    if spec.get("poses"):
        return f"the data's poses file {Path(str(spec['path'])) / str(spec['poses'])}"
    try:
        resolved = resolve(data_source(data))
    except (OSError, ValueError, KeyError):  # the data is not readable here: the layout is unknown
        return "the data's poses file"
    if resolved.layout == "uavid":
        return SEQUENCE_POSES
    return f"the data's poses file {Path(resolved.path) / POSES_FILE}"


def own_pose_span(frames: Any) -> Mapping[str, tuple[float, float]] | None:
    """The range (min, max) of ``height_m`` and ``pitch_deg`` over the evaluated frames planned with their own pose
    (``pose_source`` other than ``nominal``); None when every frame took the nominal pose."""
    if frames is None or not {"pose_source", "height_m", "pitch_deg"} <= set(frames.columns):
        return None
    own = frames[(frames["pose_source"].fillna("nominal") != "nominal") & frames["height_m"].notna()]
    if not len(own):
        return None
    return {c: (float(own[c].min()), float(own[c].max())) for c in ("height_m", "pitch_deg")}


def pose_source_text(config: Mapping[str, Any], frames: Any, data: Mapping[str, Any] | None = None) -> str:
    """The campaign's pose policy and where the evaluated frames' poses came from (the ``pose_source`` readouts;
    ``data``: the manifest's data record, which names the poses file)."""
    policy = str(config.get("poses") or "nominal")
    text = f"{POLICIES.get(policy, repr(policy))} (pose policy {policy})"
    if frames is None or "pose_source" not in frames:
        return text + "; no evaluated frame"
    counts = frames["pose_source"].fillna("").astype(str).value_counts()
    where = poses_file(data) if "frame" in counts else ""
    parts = [f"{n} frame(s) planned with {SOURCES[s].replace('{poses}', where) if s in SOURCES else repr(s)}"
             for s, n in sorted(counts.items())]
    return f"{text}; {', '.join(parts)}"


def gate_features(doc: Mapping[str, Any] | None) -> str:
    """What a frame gate file says it is: its kind and the features it reads (the file's own ``features.what``,
    else ``el.monitors.gates.features.WHAT`` of its tap)."""
    doc = doc or {}
    features = doc.get("features") or {}
    tap = str(features.get("tap") or "?")
    what = features.get("what") or WHAT.get(tap, f"the {tap!r} statistics of the frame pass")
    return f"{doc.get('kind', '?')} on {what}"


def frame_gate_text(config: Mapping[str, Any]) -> str:
    """What guards the declared operating domain in the run: the frame gate it ran (as its file says), or telemetry
    alone."""
    gate = config.get("gate")
    if not gate:
        return ("none: the operating domain is guarded by telemetry only (the declared pose and image size); "
                "a frame unlike the training data is not detected")
    path = gate.get("path")
    doc = record_body(Path(path)) if path else None
    what = gate_features(doc) if doc else "its file is not readable here"
    return f"{path} ({gate_identity(path, gate.get('sha256'), doc)}): {what}"


def gate_identity(path: str | None, recorded: Any, body: Mapping[str, Any] | None) -> str:
    """The gate file's SHA-256 (the one the AMLAS index shows) when its body is still the one the run recorded
    (``recorded``: the record's body hash); else the recorded body hash, labelled as such."""
    body_hash = f"record body SHA-256 {str(recorded)[:16]}, as the run recorded it"
    if not path or body is None or not Path(path).is_file():
        return body_hash + "; the file is not readable here"
    try:
        same = body_sha256(dict(body)) == recorded
    except (TypeError, ValueError):
        same = False
    if not same:
        return body_hash + "; the file's body differs now"
    return f"SHA-256 {sha256_file(Path(path))[:16]}"


def waivers_text(waivers: Any, shipped: bool) -> str:
    """The waiver file the gate read, or why there is none."""
    if not waivers:
        return "none" if shipped else ("none (the system file names no [waivers] file; the shipped waivers document "
                                       "the shipped system only)")
    return f"{rel(waivers)}" + (" (the shipped system's)" if shipped else "")


def report_facts(system: Any, manifest: Mapping[str, Any], images: Any = None, *,
                 size: tuple[int, int] | None = None, waivers: Any = None) -> ReportFacts:
    """The report's facts of ``system`` (an ``assurance.system.SystemFile``; None: the embedded default) and the
    run (its signed ``manifest`` and ``images`` readouts; ``size``: the evaluated frames' size)."""
    file = system if system is not None else default_system()
    shipped = bool(file.default)
    cfg = manifest.get("config") or {}
    core = cfg.get("core") or {}
    frames = _ok_frames(images)
    own = own_pose_span(frames)
    release = None
    if shipped:
        release = preset_config("release").images
    return ReportFacts(
        shipped=shipped, system=file.label, texts=facts_of_file(file),
        camera=camera_row(core, file.camera_named()), stripes=stripes_text(core, frames, size),
        pose_source=pose_source_text(cfg, frames, manifest.get("data")), frame_gate=frame_gate_text(cfg),
        waivers=waivers_text(waivers, shipped), release_images=release,
        data_provenance=file.data_note("provenance"), data_licence=file.data_note("licence"),
        data_folders=_data_folders(file), trained_by=file.provenance("trained_by"),
        model_licence=file.provenance("licence"),
        own_poses=own,
        poses_from=poses_file(manifest.get("data")) if own else "")


__all__ = ["NOT_DECLARED", "ReportFacts", "gate_features", "report_facts", "stripes_text"]
