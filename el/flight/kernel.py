"""The one decision kernel: a frame -> its pose and the declared domain -> segmentation -> the frame gate ->
the CM's candidates -> the judge -> the walk -> a ``Decision``.

Every user of the flight function runs this code: the flight loop (``el.flight.pipeline.EmergencyLanding``, a lazy judge
under the deadline), a campaign task (``assurance.campaign.task``: every configuration's verdicts from one
judging pass, each concluded here) and the ground-truth pipeline (a label-map segmenter and no monitor). What differs
between them is plugged in: how the frame is read, the segmenter, and the judge. :func:`build_parts` is the one place
their :class:`Parts` are put together (the label set taken from the network, the frame gate bound to it).

:func:`prepare` runs the stages up to the candidates and returns a :class:`Frame`; a stage that settles the decision
before the walk (a fault, a frame outside the declared domain, one the frame gate refuses, the deadline) sets
``Frame.stop``. With ``evaluate=True`` (campaigns) the stages after a refusal still run, so the readouts keep the
candidates and the monitors' verdicts, while the decision stays the refusal's. :func:`conclude` walks the judged
candidates to the decision; it never raises.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from el.base.deadline import Deadline
from el.base.decision import Candidate, Decision
from el.base.errors import BudgetExceeded
from el.classes.labels import LabelSet
from el.geometry.camera import Pose, check_geometry
from el.geometry.config import CoreConfig
from el.geometry.odd import OperatingDomain
from el.landing.core import default_area, run_core
from el.monitors.frame_gate import FrameGate, bind_frame_gate, judge_frame
from el.monitors.walk import HAZARD, Judge, Step, WalkOutcome, walk_candidates
from el.segmentation.contract import labels_of, segment_frame

REFUSALS = ("outside_odd", "out_of_domain")
"""How the reasons of the kernel's refusals begin: a frame outside the declared domain, or one the frame gate refuses,
is the default action by design, whatever the monitors would have said of its candidates."""
Clock = Callable[[], float]
Reader = Callable[[dict[str, Any]], np.ndarray]
"""Reads the frame (filling the decision's ``input`` record it is given) and returns the array the segmenter takes
and the monitors judge; its width and height are the frame's."""
POSE_SOURCES = ("nominal", "frame", "command_line")
"""Where the pose a decision was planned with came from (``input.pose.source``): the system's nominal pose, the
frame's own (a flight log, a campaign frame's sidecar), or a tool's command line (``uav-el land --height/--pitch``)."""
NOMINAL_SIZE = (3840, 2160)
logger = logging.getLogger(__name__)  # faults with their tracebacks; the decision keeps only the reason


@dataclass(frozen=True, kw_only=True)
class Parts:
    """The deployed parts a decision runs with: segmenter, label set, CM configuration, declared domain, frame gate.

    ``fault``: a fault found when the system was built (weights missing, a monitor refused): every decision is
    then the default action with it as its reason, once the frame is read. ``record``: the decision's ``config``.
    ``nominal_size``: the frame size assumed for the default area when the frame cannot be read.
    """

    segmenter: Any
    labels: LabelSet
    core: CoreConfig
    odd: OperatingDomain | None = None
    gate: FrameGate | None = None
    fault: str | None = None
    record: dict[str, Any] = field(default_factory=dict)
    nominal_size: tuple[int, int] = NOMINAL_SIZE


def build_parts(segmenter: Any, core: CoreConfig, *, labels: LabelSet | None = None, odd: OperatingDomain | None = None,
                gate: FrameGate | None = None, fault: str | None = None, record: dict[str, Any] | None = None,
                nominal_size: tuple[int, int] = NOMINAL_SIZE) -> Parts:
    """The parts a decision runs with, put together here for every user of the kernel (flight, campaign, ground
    truth). The label set is the network's (``labels_of``) unless given; a frame gate is bound to the network
    (``el.monitors.frame_gate.bind_frame_gate``: fitted on it, and it returns frame statistics), ``FrameGateError``
    otherwise, so no part set holds a gate its network cannot feed."""
    if gate is not None:
        bind_frame_gate(gate, segmenter)
    return Parts(segmenter=segmenter, labels=labels_of(segmenter) if labels is None else labels, core=core, odd=odd,
                 gate=gate, fault=fault, record=dict(record or {}), nominal_size=nominal_size)


@dataclass(frozen=True)
class FramePose:
    """The pose a frame is planned at, as its caller gives it: ``pose`` (None: the nominal ``parts.core.pose``),
    where it came from (``source``, :data:`POSE_SOURCES`; the decision records ``nominal`` without a pose) and
    ``roll_deg`` (not modelled: checked within the flat-ground model's tolerance). Checked when the kernel reads it:
    a bad one is the decision's ``fault: pose: ...``, never an exception."""

    pose: Pose | None = None
    source: str = "frame"
    roll_deg: float = 0.0


@dataclass(frozen=True, kw_only=True)
class WalkPlan:
    """How :func:`conclude` walks the judged candidates (``el.monitors.walk.walk_candidates``): the order
    (``walk``), ``evaluate_all`` (every candidate judged, even past the one selected: the readouts), and the steps
    run ``before`` and ``after`` each judgement (the flight loop's deadline)."""

    walk: str = HAZARD
    evaluate_all: bool = False
    before: Step | None = None
    after: Step | None = None


@dataclass(frozen=True)
class DecisionRecords:
    """The decision's records, filled in place: ``info`` (its ``input``) and ``timings``. A caller that gives them
    reads them while the decision runs (the flight loop's hard stop, from another thread)."""

    info: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class Frame:
    """What the kernel saw of one frame: its size and pose, the segmentation, the candidates, and ``stop``, the
    reason that settles the decision before any walk (None: the candidates are walked)."""

    info: dict[str, Any]
    timings: dict[str, float]
    core: CoreConfig
    size: tuple[int, int] | None = None
    rgb: np.ndarray | None = None
    probs: np.ndarray | None = None
    candidates: list[Candidate] = field(default_factory=list)
    stop: str | None = None
    stage: str = "read"


def frame_core(core: CoreConfig, pose: Pose | None) -> CoreConfig:
    """The core configuration of one frame: the nominal one, at the frame's pose when it brings one."""
    if pose is None:
        return core
    if not isinstance(pose, Pose):
        raise ValueError(f"pose must be an el.geometry.camera.Pose, got {type(pose).__name__}")
    values = {f.name: getattr(pose, f.name) for f in fields(pose)}
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
            raise ValueError(f"pose {name} must be a number, got {value!r}")
    return replace(core, pose=Pose(**{k: float(v) for k, v in values.items()}))  # checked again, plain floats


def pose_record(pose: Pose, *, source: str) -> dict[str, Any]:
    """The pose a decision was planned with and where it came from (:data:`POSE_SOURCES`), as its JSON records it
    (``input.pose``)."""
    if source not in POSE_SOURCES:
        raise ValueError(f"pose source must be one of {', '.join(POSE_SOURCES)}, got {source!r}")
    return {**{f.name: getattr(pose, f.name) for f in fields(pose)}, "source": source}


def _fault(stage: str, exc: BaseException, info: dict[str, Any]) -> str:
    logger.exception("fault in stage %s of the decision (input %s); default action", stage, info.get("path", "?"))
    return f"fault: {stage}: {type(exc).__name__}: {exc}"


def prepare(read: Reader, parts: Parts, *, pose: FramePose | None = None, budget: Deadline | None = None,
            clock: Clock = time.perf_counter, evaluate: bool = False, raise_faults: bool = False,
            records: DecisionRecords | None = None) -> Frame:
    """Run the stages up to the candidates; never raises (a fault is ``Frame.stop``) unless ``raise_faults`` (a
    campaign records a fault of its task with the exception itself).

    ``pose``: the frame's pose, where it came from and its roll (:class:`FramePose`; None: the nominal pose).
    ``budget``: checked between the stages. ``evaluate``: past a refusal (declared domain, frame gate) the later
    stages still run, for the readouts. ``records``: the decision's ``info`` and ``timings``, filled in place (a
    caller that stops the decision from another thread reads them; None: new ones).
    """
    budget = budget or Deadline(clock, None)
    pose = pose or FramePose()
    records = records or DecisionRecords()
    frame = Frame(info=records.info, timings=records.timings, core=parts.core)
    info, timings = frame.info, frame.timings
    roll_deg = pose.roll_deg

    def settle(reason: str) -> None:
        frame.stop = frame.stop or reason

    try:
        if budget.cancelled.is_set():  # stopped while it waited for the one before it: read nothing
            raise BudgetExceeded("decision stopped before it started")
        t = clock()
        info["frame_gate"] = None if parts.gate is None else parts.gate.record(None)
        rgb = read(info)
        frame.size, frame.rgb = (int(rgb.shape[1]), int(rgb.shape[0])), rgb
        timings["read_s"] = clock() - t
        frame.stage = "pose"
        frame.core = frame_core(parts.core, pose.pose)
        info["pose"] = pose_record(frame.core.pose, source="nominal" if pose.pose is None else pose.source)
        if roll_deg:
            info["pose"]["roll_deg"] = float(roll_deg)  # not modelled: a pose error within MAX_ROLL_DEG
        if parts.fault:
            settle(parts.fault)
            return frame
        outside = None if parts.odd is None else parts.odd.outside(frame.core.pose, frame.size)
        if outside:  # no evidence of safety there: the default action, a decision and not a fault
            settle(outside)
            if not evaluate:
                return frame
        check_geometry(frame.core.geometry(*frame.size), roll_deg=roll_deg)  # unplannable pose: a fault
        budget.check(frame.stage)

        frame.stage = "segmentation"
        t = clock()
        # with a gate, the frame's statistics come back with its probabilities, from the same pass
        probs, stats = segment_frame(parts.segmenter, rgb, stats=parts.gate is not None)
        if not isinstance(probs, np.ndarray) or not np.isfinite(probs).all():
            raise ValueError("segmentation returned non-finite scores")
        frame.probs = probs
        timings["segmentation_s"] = clock() - t
        budget.check(frame.stage)

        if parts.gate is not None:
            frame.stage = "frame_gate"
            refused = judge_frame(parts.gate, stats, info)
            if refused:  # no evidence of safety for this frame: a decision, not a fault
                settle(refused)
                if not evaluate:
                    return frame
            budget.check(frame.stage)  # no stage starts past the deadline

        frame.stage = "candidates"
        t = clock()
        frame.candidates = run_core(probs, frame.size, frame.core, clock=clock, labels=parts.labels).candidates
        timings["candidates_s"] = clock() - t
        budget.check(frame.stage)
        frame.stage = "monitoring"
    except BudgetExceeded:
        settle("timeout")
    except Exception as exc:
        if raise_faults:
            raise
        settle(_fault(frame.stage, exc, info))
    return frame


def conclude(frame: Frame, parts: Parts, judge: Judge | None, *, walk: WalkPlan | None = None,
             budget: Deadline | None = None, clock: Clock = time.perf_counter) -> tuple[Decision, WalkOutcome | None]:
    """Walk the frame's candidates with ``judge`` (None: no monitor, the CM's top candidate) to its decision, as
    ``walk`` says (:class:`WalkPlan`; None: the hazard walk, lazy, no steps around the judgements); a frame that
    stopped before the walk is the default action for its reason. Returns the decision and the walk's outcome (None:
    no walk). Never raises: a fault of the judge or the deadline is the default action. The frame is left as it is
    (a campaign concludes it once per configuration)."""
    budget = budget or Deadline(clock, None)
    walk = walk or WalkPlan()
    if frame.stop:
        return default(frame, parts, frame.stop, budget), None
    timings = dict(frame.timings)
    t = clock()
    try:
        outcome = walk_candidates(len(frame.candidates), judge, walk.walk, evaluate_all=walk.evaluate_all,
                                  before=walk.before, after=walk.after)
        judged = [c if v is None else replace(c, monitor=v)
                  for c, v in zip(frame.candidates, outcome.verdicts, strict=True)]
        timings["monitoring_s"] = clock() - t
        timings["overhead_s"] = outcome.overhead_s
        budget.check("monitoring")
    except BudgetExceeded:
        return default(frame, parts, "timeout", budget), None
    except Exception as exc:
        return default(frame, parts, _fault("monitoring", exc, frame.info), budget), None
    if outcome.selected is None:
        return default(frame, parts, outcome.reason, budget, candidates=judged, timings=timings), outcome
    timings["total_s"] = budget.elapsed()
    size = frame.size or parts.nominal_size
    return Decision(action="land", reason=outcome.reason, selected=outcome.selected, candidates=judged,
                    default_area=default_area(*size, frame.core), timings=timings, input=frame.info,
                    config=parts.record), outcome


def default(frame: Frame, parts: Parts, reason: str, budget: Deadline, *, candidates: list[Candidate] | None = None,
            timings: dict[str, float] | None = None) -> Decision:
    """The default action for ``reason``, its area on the frame (on the nominal frame and pose when that fails or
    the frame was never read); ``candidates`` and ``timings``: the frame's unless given."""
    size = frame.size or parts.nominal_size
    try:
        area = default_area(*size, frame.core)
    except Exception:  # the default area of the nominal frame: the decision itself must not fail
        logger.exception("default area of a %dx%d frame failed; using the nominal %dx%d frame", *size,
                         *parts.nominal_size)
        area = default_area(*parts.nominal_size, parts.core)
    timings = dict(frame.timings if timings is None else timings)
    timings["total_s"] = budget.elapsed()
    return Decision(action="default", reason=reason, selected=None,
                    candidates=list(frame.candidates if candidates is None else candidates),
                    default_area=area, timings=timings, input=frame.info, config=parts.record)


def decide_frame(read: Reader, parts: Parts, judge: Judge | None, *, walk: WalkPlan | None = None,
                 pose: FramePose | None = None, budget: Deadline | None = None, clock: Clock = time.perf_counter,
                 records: DecisionRecords | None = None) -> Decision:
    """One frame through the kernel: :func:`prepare` (``pose``, ``records``) then :func:`conclude` (``walk``); never
    raises."""
    budget = budget or Deadline(clock, None)
    frame = prepare(read, parts, pose=pose, budget=budget, clock=clock, records=records)
    return conclude(frame, parts, judge, walk=walk, budget=budget, clock=clock)[0]


__all__ = ["NOMINAL_SIZE", "POSE_SOURCES", "REFUSALS", "DecisionRecords", "Frame", "FramePose", "Parts", "WalkPlan",
           "build_parts", "conclude", "decide_frame", "default", "frame_core", "pose_record", "prepare"]
