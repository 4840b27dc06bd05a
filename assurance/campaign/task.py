"""A campaign's configuration and one task of it: a (perturbation, severity, image) through the flight kernel.

The task reads and perturbs its frame (seeded per image), runs the kernel's stages (``el.flight.kernel.prepare``: the
pose
and the declared domain, segmentation, the frame gate, the CM's candidates) **once**, judges every candidate with
every monitor configuration in one pass, sharing work between them (``judging``), and concludes each
configuration's decision with the kernel (``el.flight.kernel.conclude``), so that what a campaign measures is what
flies.

A fault of the frame (reading, pose, segmentation, the gate, the candidates) is the task's: one row records it. A
fault of one configuration (building its monitor, a model fitted on another network, judging a candidate) is that
configuration's: its row records it and every other configuration's readouts of the task are kept.
"""

from __future__ import annotations

import hashlib
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from assurance.campaign import readouts
from assurance.campaign.frame_cache import cached, file_key
from assurance.campaign.frames import (
    check_frame_pose,
    clearance_of,
    frame_gate,
    frame_pose_of,
    frame_truth,
    gate_columns,
)
from assurance.campaign.judging import _timed, judge_candidates
from assurance.campaign.truth import true_hazard
from assurance.dataio.poses import check_policy
from assurance.dataio.uavid import Sample
from assurance.perturbations import PERTURBATIONS, TRAITS, perturb, severities_of
from el.base.deadline import Deadline
from el.base.imageio import read_image_meta
from el.flight.kernel import DecisionRecords, Frame, FramePose, Parts, WalkPlan, build_parts, conclude, prepare
from el.geometry.config import CoreConfig, check_seed
from el.geometry.odd import OperatingDomain
from el.landing.core import default_area
from el.monitors import DEMO_GRID, build_monitor, parse_monitor_spec
from el.monitors.frame_gate import GateFile
from el.monitors.spec import walk_of
from el.monitors.walk import walk_candidates
from el.segmentation.contract import labels_of


# ------------------------------------------------------------------------------------------------
# Configuration
# ------------------------------------------------------------------------------------------------
def scenario_pairs(perturbations: Sequence[str], severities: Sequence[int],
                   caps: Mapping[str, int] | None = None) -> list[tuple[str, int]]:
    """A campaign's (perturbation, severity) pairs in order: each perturbation at every severity (one not graded,
    'none', at the first only), a capped one at those up to its cap, else at the cap itself."""
    out: list[tuple[str, int]] = []
    for p in perturbations:
        sev = [int(s) for s in severities_of(p, severities)]
        cap = (caps or {}).get(p)
        if cap is not None and TRAITS[p].graded:
            sev = [s for s in sev if s <= cap] or [int(cap)]
        out.extend((p, s) for s in sev)
    return out


@dataclass(frozen=True, kw_only=True)
class CampaignConfig:
    """What a campaign evaluates. Recorded in the run manifest; a resumed run must match it."""

    perturbations: tuple[str, ...]
    severities: tuple[int, ...] = (3,)
    monitors: tuple[str, ...] = DEMO_GRID
    images: int | None = None  # the first N images of the data set (sorted); None: all
    seed: int = 0
    patch_margin: float = 0.25
    patch_max_side: int | None = None
    weights: str | dict[str, Any] | None = None  # None: the shipped weights; a dict: a system file's model
    core: CoreConfig = field(default_factory=CoreConfig)
    poses: str = "nominal"  # which pose plans each frame: assurance.dataio.poses.POLICIES
    # the declared operating domain (a manifest's record, OperatingDomain.to_dict(), is read back to one); None: none
    odd: OperatingDomain | None = None
    # the frame gate, pinned to the body SHA-256 the run records (a manifest's {"path", "sha256"} is read back to
    # one): the flight's type (el.monitors.frame_gate.GateFile); None: none
    gate: GateFile | None = None
    time_budget_s: float | None = None  # the flight's deadline (with the task's clock); None: none, so that the
    # readouts do not depend on the machine's speed
    severity_caps: dict[str, int] | None = None  # per perturbation, a declared maximum below the severities (it runs
    # at those up to it, else at it: scenario_pairs; assurance.campaign.perturbation_plan); None: none

    def __post_init__(self) -> None:
        unknown = [p for p in self.perturbations if p not in PERTURBATIONS]
        if unknown:
            raise ValueError(f"unknown perturbation(s) {unknown}; valid: {', '.join(PERTURBATIONS)}")
        if not self.perturbations:
            raise ValueError("a campaign needs at least one perturbation")
        bad = [s for s in self.severities if not (isinstance(s, int) and 1 <= s <= 5)]
        if bad or not self.severities:
            raise ValueError(f"severities must be integers in 1..5, got {list(self.severities)}")
        if not self.monitors:
            raise ValueError("a campaign needs at least one monitor configuration")
        canon = []
        for m in self.monitors:
            spec = parse_monitor_spec(m)
            if spec is None:
                raise ValueError("'none' is not a monitor configuration to evaluate (the CM alone is in every row)")
            canon.append(spec.name)
        if len(set(canon)) != len(canon):
            raise ValueError(f"duplicate monitor configurations in {list(self.monitors)}")
        object.__setattr__(self, "monitors", tuple(canon))
        if self.images is not None and self.images < 1:
            raise ValueError(f"images must be >= 1, got {self.images}")
        check_seed(self.seed)
        check_policy(self.poses)
        if self.odd is not None and not isinstance(self.odd, OperatingDomain):
            object.__setattr__(self, "odd", OperatingDomain.from_dict(self.odd))  # a malformed record fails here
        object.__setattr__(self, "gate", GateFile.of(self.gate))
        if self.gate is not None and self.gate.sha256 is None:
            raise ValueError(f"gate {self.gate.path}: a campaign pins its frame gate's body SHA-256")
        bad_caps = {p: c for p, c in (self.severity_caps or {}).items()
                    if p not in PERTURBATIONS or isinstance(c, bool) or not isinstance(c, int) or not 1 <= c <= 5}
        if bad_caps:
            raise ValueError(f"severity caps must map perturbations to integers in 1..5, got {bad_caps}")

    def scenarios(self) -> list[tuple[str, int]]:
        """(perturbation, severity) pairs; one not graded by severity ('none') is evaluated once, at the first."""
        return scenario_pairs(self.perturbations, self.severities, self.severity_caps)

    def to_dict(self) -> dict[str, Any]:
        """The manifest's ``config``; ``poses`` only when not nominal, so a nominal run records as before."""
        d = asdict(self)
        d["core"] = self.core.to_dict()
        d["odd"] = None if self.odd is None else self.odd.to_dict()
        d["gate"] = None if self.gate is None else self.gate.to_dict()
        if self.poses == "nominal":
            del d["poses"]
        for key in ("odd", "gate", "time_budget_s", "severity_caps"):
            if d[key] is None:
                del d[key]
        return d


# ------------------------------------------------------------------------------------------------
# One task
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    """One (perturbation, severity, image) of a campaign."""

    perturbation: str
    severity: int
    sample: Sample

    @property
    def shard_name(self) -> str:
        return readouts.shard_name(self.perturbation, self.severity, self.sample.key)


def frame_identity(rgb: np.ndarray) -> str:
    """What a frame is, whatever layout, folder or file format it was read from: the SHA-256 (hex) of its decoded
    pixels and shape. A perturbation's randomness is keyed by it, so the same frames read through two layouts (or
    converted from JPEG to PNG losslessly) get the same noise."""
    pixels = np.ascontiguousarray(rgb)
    h = hashlib.sha256(f"{pixels.dtype.str}{pixels.shape}".encode())
    h.update(memoryview(pixels).cast("B"))
    return h.hexdigest()


def task_seed(seed: int, frame: str, perturbation: str, severity: int) -> list[int]:
    """Seed sequence of a task's perturbation: independent of the order and place tasks run, and of the layout the
    frame was read through (``frame``: its :func:`frame_identity`)."""
    digest = hashlib.sha256(f"{frame}|{perturbation}|{severity}".encode()).digest()
    return [seed, int.from_bytes(digest[:8], "little")]


def task_parts(config: CampaignConfig, segmenter: Any, labels: Any) -> Parts:
    """The flight kernel's parts for a campaign's frames (``el.flight.kernel.build_parts``, as flight builds them): its
    network, label set, CM configuration, declared domain and frame gate (read once per worker, refused when its file
    changed, it was fitted on another network or the network returns no frame statistics)."""
    return build_parts(segmenter, config.core, labels=labels, odd=config.odd, gate=frame_gate(config.gate, segmenter))


def run_task(task: Task, config: CampaignConfig, segmenter: Any, *, clock: Callable[[], float] = time.perf_counter,
             world_clearance: Callable[..., Any] | None = None,
             expected_models: dict[str, str] | None = None) -> dict[str, list[dict[str, Any]]]:
    """Evaluate one task: the flight kernel (``el.flight.kernel``) on the perturbed frame, every configuration's
    verdicts
    from one judging pass (``judging``), each configuration's decision concluded by the kernel, and the readout rows
    of its images and candidates tables. A frame the kernel refuses (declared domain, frame gate) is decided as in
    flight while every monitor's verdicts on its candidates stay in the readouts; a monitor model other than
    ``expected_models``'s: a fault."""
    s = task.sample
    base = {"key": s.key, "sequence": s.sequence, "frame": s.frame, "perturbation": task.perturbation,
            "severity": task.severity}
    t0 = clock()
    budget = Deadline(clock, config.time_budget_s)
    try:
        judged = _judged_frame(task, config, segmenter, clock, budget, expected_models)
    except Exception as exc:  # a bad image is a recorded fault, never a crash of the campaign
        fault = f"{type(exc).__name__}: {exc}"
        row = {**base, "monitor": "", "fault": fault, "traceback": traceback.format_exc(limit=3)}
        return {"images": [row], "candidates": []}
    return _readout_rows(judged, config, base, clock, t0, budget, world_clearance)


@dataclass
class _Judged:
    """One campaign frame through the kernel: the frame, its parts, its truth, every configuration's verdicts."""

    frame: Frame
    parts: Parts
    sample: Sample
    ids: np.ndarray
    monitors: list[Any]
    verdicts: list[list[Any]]
    pose_cols: dict[str, Any]
    meta: dict[str, Any]
    faults: dict[int, str] = field(default_factory=dict)  # configuration index -> its fault on this task
    tracebacks: dict[int, str] = field(default_factory=dict)


def _judged_frame(task: Task, config: CampaignConfig, segmenter: Any, clock: Callable[[], float], budget: Deadline,
                  expected_models: dict[str, str] | None) -> _Judged:
    """The task's frame read, perturbed and run through the kernel's stages, then judged by every configuration
    at once; raises on a fault of the task."""
    s = task.sample
    pose, roll, pose_cols = frame_pose_of(config, s)
    labels = labels_of(segmenter)
    parts = task_parts(config, segmenter, labels)
    meta: dict[str, Any] = {}
    truth: list[np.ndarray] = []
    timings: dict[str, float] = {"read_s": 0.0}  # the readouts' column order: read, perturb, segmentation, ...

    def read(info: dict[str, Any]) -> np.ndarray:
        rgb, found = cached("image", file_key(s.image_path), lambda: read_image_meta(s.image_path))
        meta.update(found)  # EXIF orientation
        check_frame_pose(config, s, pose, roll, (rgb.shape[1], rgb.shape[0]))
        truth.append(frame_truth(s, labels, rgb.shape[:2])[1])
        identity = cached("frame identity", file_key(s.image_path), lambda: frame_identity(rgb))  # once per scene
        rng = np.random.default_rng(task_seed(config.seed, identity, task.perturbation, task.severity))
        hd, timings["perturb_s"] = _timed(clock, perturb, rgb, task.perturbation, task.severity, rng)
        return hd

    frame = prepare(read, parts, pose=FramePose(pose, roll_deg=roll), budget=budget, clock=clock, evaluate=True,
                    raise_faults=True, records=DecisionRecords(timings=timings))
    timings["read_s"] -= timings.get("perturb_s", 0.0)
    if frame.stop == "timeout":  # decided at the deadline, as in flight: no candidate is judged
        frame.candidates = []
    monitors, faults, tracebacks = _configurations(config, segmenter, labels, clock, expected_models)
    t = clock()
    verdicts = judge_candidates(frame.rgb, frame.candidates, monitors, segmenter, seed=config.seed, clock=clock,
                                frame_probs=frame.probs, faults=faults)
    timings["monitoring_s"] = clock() - t
    return _Judged(frame, parts, s, truth[0], monitors, verdicts, pose_cols, meta, faults, tracebacks)


def _configurations(config: CampaignConfig, segmenter: Any, labels: Any, clock: Callable[[], float],
                    expected_models: dict[str, str] | None) -> tuple[list[Any], dict[int, str], dict[int, str]]:
    """Each configuration's monitor, built and checked on its own: a monitor that cannot be built, was fitted on
    another network or runs another model file than the run recorded is that configuration's fault (index ->
    ``"Error: message"``, and its traceback), never the task's."""
    monitors: list[Any] = []
    faults: dict[int, str] = {}
    tracebacks: dict[int, str] = {}
    for i, name in enumerate(config.monitors):
        try:
            monitor = build_monitor(name, margin=config.patch_margin, max_side=config.patch_max_side, clock=clock,
                                    labels=labels, network_classes=getattr(segmenter, "network_classes", None))
            if monitor is not None:
                monitor.check_network(segmenter)  # a monitor fitted on another network: a fault, never a readout
            if expected_models is not None:
                _check_models([name], [monitor], expected_models)
        except Exception as exc:  # this configuration's fault; the others are judged
            monitor = None
            faults[i] = f"{type(exc).__name__}: {exc}"
            tracebacks[i] = traceback.format_exc(limit=3)
        monitors.append(monitor)
    return monitors, faults, tracebacks


def _readout_rows(j: _Judged, config: CampaignConfig, base: dict[str, Any], clock: Callable[[], float], t0: float,
                  budget: Deadline, world_clearance: Callable[..., Any] | None) -> dict[str, list[dict[str, Any]]]:
    """Each configuration's decision (the kernel's) and its readout rows (images and candidates tables)."""
    frame, labels = j.frame, j.parts.labels
    cands = frame.candidates
    W, H = frame.size
    truth = [true_hazard(j.ids, c.disc, labels=labels) for c in cands]
    clearance = clearance_of(world_clearance, j.sample, (W, H), cands)
    area = default_area(W, H, frame.core)
    h_default = true_hazard(j.ids, area, labels=labels)
    gate_cols = gate_columns(j.parts.gate, frame.info)
    image_rows, cand_rows = [], []
    for m, name in enumerate(config.monitors):
        if m in j.faults:  # this configuration faulted on this task: its row says so, the others are kept
            image_rows.append({**base, "monitor": name, "fault": j.faults[m],
                               "traceback": j.tracebacks.get(m, "")})
            continue
        column = [j.verdicts[k][m] for k in range(len(cands))]
        decision, outcome = conclude(frame, j.parts, column.__getitem__,
                                     walk=WalkPlan(walk=walk_of(name), evaluate_all=True), budget=budget, clock=clock)
        if outcome is None:  # a refused frame: its walk is still read out (overhead, candidates examined)
            outcome = walk_candidates(len(cands), column.__getitem__, walk_of(name), evaluate_all=True)
        sel = decision.selected
        h_decision = h_default if sel is None else truth[sel]
        image_rows.append({
            **base, "monitor": name, "fault": "", "candidates": len(cands), "action": decision.action,
            "reason": decision.reason, "selected": -1 if sel is None else sel, "h_default": h_default,
            "h_top": truth[0] if cands else float("nan"), "h_decision": h_decision,
            "decision_unsafe": bool(h_decision >= 1.0),
            "clearance_decision_m": clearance[sel] if sel is not None else float("nan"),
            "overhead_s": float(outcome.overhead_s),
            "default_x": area.x, "default_y": area.y, "default_r": area.radius_px, "width": W, "height": H,
            **j.pose_cols, **j.meta, **gate_cols, **frame.timings, "total_s": clock() - t0,
        })
        for k, c in enumerate(cands):
            cand_rows.append({
                **base, "monitor": name, "rank": k, "x": c.x, "y": c.y, "radius_px": c.radius_px,
                "hazard": c.hazard, "hazard_semantic": c.hazard_semantic, "hazard_distance": c.hazard_distance,
                "true_hazard": truth[k], "true_unsafe": bool(truth[k] >= 1.0), "clearance_m": clearance[k],
                "accepted": bool(column[k].accepted), "reason": column[k].reason, "seconds": float(column[k].seconds),
                "score": column[k].score, "threshold": j.monitors[m].threshold,
                "selected": sel == k, "examined": k < outcome.examined,
            })
    return {"images": image_rows, "candidates": cand_rows}


def _check_models(names: Sequence[str], monitors: Sequence[Any], expected: dict[str, str]) -> None:
    for name, monitor in zip(names, monitors, strict=True):
        have, want = getattr(monitor, "model_sha256", None), expected.get(name)
        if have != want:
            raise ValueError(f"monitor {name!r} runs model {have}, the run recorded {want} "
                             "(its model file changed during the run)")
