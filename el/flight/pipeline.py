"""The monitored emergency-landing decision loop (docs/architecture.md section 3): the function a flight computer calls.

image -> segmentation (working resolution) -> CM candidates ranked by hazard -> runtime monitor on the
HD image, candidate by candidate -> the first accepted candidate, else the default action (parachute).

Fail safe (EL-R03, EL-R06, EL-R07): ``EmergencyLanding.decide`` never raises. An unreadable or
malformed image, missing or altered weights, non-finite scores, an exception in the CM or a monitor,
or a time budget exceeded (read from an injectable clock) all end in the default action, with the
reason recorded in ``Decision.reason``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from el.base.deadline import DEFAULT_TIME_BUDGET_S, Deadline, active, run_with_deadline
from el.base.decision import Decision, Disc, MonitorVerdict
from el.base.errors import BudgetExceeded
from el.base.hashing import sha256_bytes
from el.base.imageio import MAX_PIXELS, check_max_pixels, read_image_hashed
from el.base.rgb import check_rgb
from el.classes.labels import UAVID
from el.flight.kernel import (
    DecisionRecords,
    Frame,
    FramePose,
    Parts,
    WalkPlan,
    build_parts,
    conclude,
    default,
    frame_core,
    prepare,
)
from el.geometry.camera import Pose
from el.geometry.config import CoreConfig, check_seed
from el.geometry.odd import OperatingDomain
from el.monitors import CandidateContext, Monitor, build_monitor, monitor_name, parse_monitor_spec
from el.monitors.calibration import check_card_monitor, check_card_spec, load_calibration
from el.monitors.capabilities import check_monitor_capabilities
from el.monitors.frame_gate import GateFile
from el.monitors.patch_judge import batch_judge
from el.monitors.walk import HAZARD, SCORE, Judge, Step
from el.segmentation.contract import check_model, labels_of
from el.segmentation.factory import load_model

Clock = Callable[[], float]
DEPLOYED_MONITOR = "verifier:fuse=learned,walk=score,threshold=0.8971373147264656"
"""The shipped runtime monitor, chosen on the validation split (docs/results.md, docs/monitors.md): the candidate
verifier (``el/monitors/data/verifier.json``, a CNN of its own on the candidate's pixels) fused with the learned
candidate monitor (``el/monitors/data/learned.json``), candidates walked by the fused score (``el.monitors.walk``),
at the threshold of its calibration card :data:`DEPLOYED_CALIBRATION` (a test checks they agree)."""
DEPLOYED_CALIBRATION = Path(__file__).resolve().parents[1] / "monitors" / "data" / "calibration.json"
DEPLOYED_GATE: Path | None = Path(__file__).resolve().parents[1] / "monitors" / "data" / "frame_gate.json"
"""The frame gate the command line deploys when it runs the shipped network (None: none): a Mahalanobis gate on the
frame pass's trunk statistics, fitted and thresholded on 3840x2160 training and validation frames under the
in-domain perturbations (docs/results.md). ``PipelineConfig.gate`` is what the flight code deploys; the
command line sets it to this unless ``--gate``/``[monitor] gate`` say otherwise."""
_NOT_BUILT = {"model": "segmentation model not loaded", "monitor": "runtime monitor {!r} not built",
              "frame_gate": "frame gate not usable"}
MIN_FRAME_SIZE = 16  # px: the smallest frame side the segmenter takes (el.segmentation.inference.MIN_SIZE)
logger = logging.getLogger(__name__)  # faults with their tracebacks; the decision keeps only the reason


@dataclass(frozen=True)
class FrameFile:
    """An image file read and decoded once by the flight reader (:meth:`read`: size capped from the header, hashed
    while decoded): a tool that needs the pixels too (``uav-el land --overlay``) decodes the frame once and hands it
    to :meth:`EmergencyLanding.decide`, which records it as the file it was read from (path, SHA-256, EXIF)."""

    path: Path
    rgb: np.ndarray
    meta: dict[str, int]
    sha256: str
    read_s: float = 0.0

    @classmethod
    def read(cls, path: str | Path, *, max_pixels: int = MAX_PIXELS) -> FrameFile:
        """Read and decode ``path`` (``el.base.imageio.read_image_hashed``; its one-line error for a bad file);
        ``read_s``: the seconds it took, which a decision on it counts against its budget as if it had read it."""
        t = time.perf_counter()
        rgb, meta, digest = read_image_hashed(path, max_pixels=max_pixels)
        return cls(Path(path), rgb, meta, digest, time.perf_counter() - t)


@dataclass(frozen=True, kw_only=True)
class PipelineConfig:
    """Everything that shapes a decision besides the image and the model weights.

    Parameters
    ----------
    core : CoreConfig
        CM parameters (geometry, safety radius, candidates, ranking).
    monitor : str or None
        Monitor spec (``"lhd"``, ``"lhd+ch:tau=0.25"``, ``"lhd+mcd:n=10,rho=0.9"``,
        ``"learned:walk=score"``, ...); None or ``"none"``: no runtime monitor (the CM's top candidate is
        taken). Default: :data:`DEPLOYED_MONITOR`, the shipped calibrated configuration.
    time_budget_s : float or None
        Seconds from the call to the decision; past it, the default action with reason "timeout".
        10 s by default: the slowest shipped configuration (MC dropout, n = 30) needs a few seconds
        per examined candidate on a laptop CPU. None disables the budget (evaluation campaigns,
        whose readouts must not depend on the machine's speed).
    evaluate_all : bool
        Evaluation mode: every candidate gets a monitor verdict (readouts for the metrics); the
        decision still follows the ranked walk, and the walk's own monitoring time is reported
        as ``timings["overhead_s"]``.
    seed : int
        Seed of MC dropout (candidate k uses ``seed + k``).
    patch_margin : float
        Context around a candidate's disc in the monitor's HD patch, as a fraction of its radius.
    patch_max_side : int or None
        Downscale HD patches whose side exceeds this (None: native resolution).
    nominal_size : (int, int)
        Input size assumed for the default area when the image cannot be read.
    calibration : path or None
        A calibration card (``uav-el calibrate``): the monitor runs at the card's threshold. The card
        must calibrate ``monitor``; a missing or altered card is a fault (default action).
    hard_stop : bool
        With a budget and the real clock (``time.perf_counter``), the decision runs in a worker thread and
        ``decide`` returns the default action ("timeout") at the deadline even while a stage that has no
        checkpoint (a forward pass, a decode) is still running; the stopped decision ends at its next
        checkpoint (``el.base.deadline``), an ONNX Runtime run in flight at once (cancelled: ``RunOptions.terminate``).
        False: the cooperative checks, and with the real clock ONNX Runtime runs cancelled at the deadline (a timer);
        an injected clock: the cooperative checks alone.
    max_pixels : int
        Largest frame accepted, in pixels (:data:`el.base.imageio.MAX_PIXELS`, 8K plus a quarter by default): a file
        whose header claims more is refused before decoding (default action, the reason naming the file).
    gate : GateFile, path or None
        A frame gate (``uav-el fit-gate``, ``el.monitors.frame_gate``) scoring the frame pass's own statistics: a
        frame above its threshold ends in the default action (``out_of_domain: frame gate ...``); its score and
        threshold are in every decision's ``input.frame_gate`` (null: no gate). A bad gate file, or a pinned one
        whose body changed, is a fault. A path is read as an unpinned ``GateFile``, the type the campaign's
        configuration pins to the hash its run records.
    odd : OperatingDomain or None
        The declared operating domain (``el.geometry.odd``): a frame whose pose or size is outside it ends in the
        default action with reason ``outside_odd: <dimension> ...`` (a decision, not a fault). None: no
        declaration is checked.
    """

    core: CoreConfig = field(default_factory=CoreConfig)
    monitor: str | None = DEPLOYED_MONITOR
    time_budget_s: float | None = DEFAULT_TIME_BUDGET_S
    evaluate_all: bool = False
    seed: int = 0
    patch_margin: float = 0.25
    patch_max_side: int | None = None
    nominal_size: tuple[int, int] = (3840, 2160)
    calibration: str | None = None
    gate: GateFile | None = None
    odd: OperatingDomain | None = None
    max_pixels: int = MAX_PIXELS
    hard_stop: bool = True

    def __post_init__(self) -> None:
        parse_monitor_spec(self.monitor)  # a bad spec fails here, before any image
        object.__setattr__(self, "gate", GateFile.of(self.gate))
        check_max_pixels(self.max_pixels)
        if self.time_budget_s is not None and not (math.isfinite(self.time_budget_s) and self.time_budget_s > 0):
            raise ValueError(f"time_budget_s must be a positive number of seconds or None, got {self.time_budget_s!r}")
        check_seed(self.seed)
        if self.odd is not None and not isinstance(self.odd, OperatingDomain):
            raise ValueError(f"odd must be an el.geometry.odd.OperatingDomain or None, got {type(self.odd).__name__}")

    @property
    def monitor_name(self) -> str:
        return monitor_name(self.monitor)

    def to_dict(self) -> dict[str, Any]:
        return {
            "pipeline": "model",
            "monitor": self.monitor_name,
            "time_budget_s": self.time_budget_s,
            "evaluate_all": self.evaluate_all,
            "seed": self.seed,
            "patch_margin": self.patch_margin,
            "patch_max_side": self.patch_max_side,
            "core": self.core.to_dict(),
            **({"calibration": self.calibration} if self.calibration else {}),
            **({"gate": self.gate.path} if self.gate else {}),
            **({"odd": self.odd.to_dict()} if self.odd is not None else {}),
            **({"max_pixels": self.max_pixels} if self.max_pixels != MAX_PIXELS else {}),
            **({} if self.hard_stop else {"hard_stop": False}),
        }


class EmergencyLanding:
    """The EL system around one segmentation model and one runtime monitor.

    Construction never raises for a model or monitor problem: the fault is kept and every
    decision is then the default action with that fault as its reason.

    Parameters
    ----------
    config : PipelineConfig
    segmenter : object with ``predict_frame``, ``predict_patch`` and ``mc_dropout``
        (``el.segmentation.Segmenter``); loaded from ``weights`` (or the shipped weights) if None.
    weights : path, optional
        Weights file to load when no segmenter is given.
    clock : callable returning seconds
        Time source of the budget and the timings (inject a fake one in tests).
    """

    def __init__(
        self,
        config: PipelineConfig | None = None,
        *,
        segmenter: Any = None,
        weights: str | Path | None = None,
        clock: Clock = time.perf_counter,
        log: Any = None,
    ) -> None:
        self.config = config or PipelineConfig()
        self.clock = clock
        # an el.flight.flightlog.FlightLog: each decision appended to it (opt-in; its write never raises)
        self.log = log
        self._lock = threading.Lock()
        self.fault: str | None = None
        self.errors: dict[str, Exception] = {}
        self.segmenter = segmenter
        self.monitor: Monitor | None = None
        self.walk = HAZARD
        self.labels = UAVID
        try:
            if segmenter is None:
                self.segmenter = load_model(weights, working_width=self.config.core.working_width)
            else:
                check_model(segmenter)
            self.labels = labels_of(self.segmenter)  # the system's label set is the one its network segments into
        except Exception as exc:  # missing/altered weights: every decision is the default action
            self._refuse("model", exc)
        try:
            spec = calibrated_spec(self.config.monitor, self.config.calibration)
            self.walk = getattr(parse_monitor_spec(spec), "walk", HAZARD)
            self.monitor = build_monitor(
                spec, margin=self.config.patch_margin,
                max_side=self.config.patch_max_side, clock=clock, labels=self.labels,
            )
            check_monitor_bindings(self.monitor, spec, self.config.calibration, self.segmenter)
        except Exception as exc:
            self._refuse("monitor", exc)
        gate = None
        if self.config.gate:
            try:
                gate = self.config.gate.load()
            except Exception as exc:
                self._refuse("frame_gate", exc)
        self.parts = self._parts(gate if self.segmenter is not None else None)  # no network: no gate to bind
        self.gate = self.parts.gate

    def _refuse(self, part: str, exc: Exception) -> None:
        """Keep a part that could not be built (``errors``; the first is every decision's ``fault``), with its
        traceback in the log. Called inside the ``except`` block."""
        self.errors.setdefault(part, exc)
        self.fault = self.fault or f"fault: {part}: {type(exc).__name__}: {exc}"
        logger.exception("%s; every decision will be the default action", _NOT_BUILT[part].format(self.config.monitor))

    def _parts(self, gate: Any) -> Parts:
        """The deployed parts the kernel decides with (``el.flight.kernel.build_parts``, built once); a gate the network
        cannot carry (fitted on another, or no frame statistics) is a fault and left out."""
        cfg = self.config

        def build(frame_gate: Any) -> Parts:
            return build_parts(self.segmenter, cfg.core, labels=self.labels, odd=cfg.odd, gate=frame_gate,
                               fault=self.fault, record=cfg.to_dict(), nominal_size=cfg.nominal_size)

        try:
            return build(gate)
        except Exception as exc:
            self._refuse("frame_gate", exc)
            return build(None)

    # -- the decision ----------------------------------------------------------------------------
    def decide(self, image: np.ndarray | str | Path | FrameFile, pose: Pose | None = None, *,
               pose_source: str = "frame") -> Decision:
        """Decide where to land for one frame (:meth:`decide_now`) and append the decision to the flight log when
        one was given (``log``, ``el.flight.flightlog``); never raises."""
        decision = self.decide_now(image, pose, pose_source=pose_source)
        if self.log is not None:
            self.log.write(decision, segmenter=self.segmenter, frame=getattr(image, "rgb", image))
        return decision

    def decide_now(self, image: np.ndarray | str | Path | FrameFile, pose: Pose | None = None, *,
                   pose_source: str = "frame") -> Decision:
        """Decide where to land for one frame (an RGB uint8 array, an image file, or a :class:`FrameFile` already
        decoded); never raises.

        ``pose``: the camera's height and pitch when the frame was taken (from the flight log); None is the
        configured nominal pose (``config.core.pose``). It sets the safety radius in pixels and is recorded in the
        decision's ``input.pose`` with ``pose_source`` (``el.flight.kernel.POSE_SOURCES``: ``frame``, or
        ``command_line``
        for a pose typed by hand). The decision is the kernel's (``el.flight.kernel``), with this system's parts and its
        monitor judging candidates lazily under the deadline.
        """
        cfg = self.config
        budget = Deadline(self.clock, cfg.time_budget_s)
        if isinstance(image, FrameFile) and self.clock is time.perf_counter:
            budget.start -= image.read_s  # the decode done before the call counts, as decide(path) counts it
        timings: dict[str, float] = {}
        info: dict[str, Any] = {}
        if not (cfg.hard_stop and cfg.time_budget_s is not None and self.clock is time.perf_counter):
            with active(budget):
                return self._decide(image, (pose, pose_source), budget, timings, info)

        def locked() -> Decision:  # one decision at a time: a stopped one ends at its next checkpoint
            with self._lock:
                return self._decide(image, (pose, pose_source), budget, timings, info)

        finished, decision = run_with_deadline(locked, budget)
        if finished:
            return decision
        seen = dict(info)  # the worker sets width, then height
        frame = Frame(info=seen, timings=dict(timings), core=cfg.core,
                      size=(seen["width"], seen["height"]) if "height" in seen else None)
        try:  # the hard stop: the default action at the deadline, on what the stopped decision had read
            frame.core = frame_core(cfg.core, pose)
        except Exception:
            pass
        return default(frame, self.parts, "timeout", budget)

    def _decide(self, image: np.ndarray | str | Path | FrameFile, pose: tuple[Pose | None, str], budget: Deadline,
                timings: dict[str, float], info: dict[str, Any]) -> Decision:
        """The kernel's decision, with ``budget`` checked between stages and (as the active deadline) inside them;
        ``pose``: the frame's pose and where it came from."""
        parts = self.parts
        frame = prepare(lambda record: self._read(image, record), parts, pose=FramePose(pose[0], pose[1]),
                        budget=budget, clock=self.clock, records=DecisionRecords(info, timings))
        if isinstance(image, FrameFile) and "read_s" in frame.timings:
            frame.timings["read_s"] += image.read_s  # decoded before the call (FrameFile.read)
        judge, before, after = self._judge(frame, budget)
        walk = WalkPlan(walk=self.walk, evaluate_all=self.config.evaluate_all, before=before, after=after)
        return conclude(frame, parts, judge, walk=walk, budget=budget, clock=self.clock)[0]

    # -- stages ----------------------------------------------------------------------------------
    def _read(self, image: np.ndarray | str | Path | FrameFile, info: dict[str, Any]) -> np.ndarray:
        if isinstance(image, str | Path):
            info["path"] = str(Path(image))  # recorded even when the file cannot be read
            image = FrameFile.read(image, max_pixels=self.config.max_pixels)  # read once, hashed while decoded
        if isinstance(image, FrameFile):
            info["path"], info["sha256"] = str(image.path), image.sha256
            info.update(image.meta)  # exif_orientation, when one was applied
            rgb = image.rgb
        else:
            rgb = image
            if not isinstance(rgb, np.ndarray):
                raise ValueError(f"image must be a numpy array or a path, got {type(rgb).__name__}")
            info["path"] = "<array>"
            check_rgb(rgb, "image", min_size=0)  # shape and type now; the size once the input is recorded
            info["sha256"] = sha256_bytes(np.ascontiguousarray(rgb).tobytes())
        info["width"], info["height"] = int(rgb.shape[1]), int(rgb.shape[0])
        rgb = check_rgb(rgb, "image", min_size=MIN_FRAME_SIZE)
        if rgb.shape[0] * rgb.shape[1] > self.config.max_pixels:  # an array (a file was checked from its header)
            raise ValueError(f"{info['path']}: image of {rgb.shape[1]}x{rgb.shape[0]} pixels exceeds the limit of "
                             f"{self.config.max_pixels} pixels (max_pixels)")
        return rgb

    def _judge(self, frame: Frame, budget: Deadline) -> tuple[Judge | None, Step | None, Step | None]:
        """The flight judge: this system's monitor on one candidate at a time, the budget checked before and after
        each judgement of the deciding walk (evaluation-only judgements past the decision are not budgeted)."""
        if self.monitor is None or frame.stop:  # no runtime monitor: the CM's top candidate
            return None, None, None
        monitor, rgb, probs = self.monitor, frame.rgb, frame.probs
        budgeted = self.config.time_budget_s is not None
        has_chunks = hasattr(monitor, "between")  # MC dropout: the budget binds between its chunks too

        def before(k: int, real: bool) -> None:
            if has_chunks:
                monitor.between = budget.ahead if (budgeted and real) else None
            if real:
                budget.check("monitoring")

        def after(k: int, real: bool) -> None:  # the hazard walk stops as soon as its judgement overran
            if real and budgeted and self.walk == HAZARD and budget.elapsed() > self.config.time_budget_s:
                raise BudgetExceeded("time budget exceeded during monitoring")

        def judge(k: int) -> MonitorVerdict:
            cand = frame.candidates[k]
            context = None if probs is None else CandidateContext(cand, probs, (rgb.shape[1], rgb.shape[0]))
            return monitor.check(rgb, cand, self.segmenter, seed=self.config.seed + k, context=context)

        if self.walk == SCORE and hasattr(monitor, "check_many"):  # every candidate is judged: all in one call
            return batch_judge(monitor, rgb, frame.candidates, self.segmenter, probs=probs,
                               seed=self.config.seed), before, after
        return judge, before, after


def check_monitor_bindings(monitor: Monitor | None, spec: str | None, calibration: str | Path | None,
                           segmenter: Any = None) -> None:
    """Refuse a monitor fitted on another network than ``segmenter``, and a threshold calibrated on another
    fitted model or another network: the card given, else the deployed card when ``spec`` is the deployed
    configuration; and a monitor needing a capability the network lacks (MC dropout on an ONNX file).
    ``segmenter`` None: the network is not checked here (it could not be loaded)."""
    if monitor is not None and segmenter is not None:
        monitor.check_network(segmenter)
        check_monitor_capabilities(monitor, segmenter)
    card = calibration or (DEPLOYED_CALIBRATION if is_deployed(spec) else None)
    if card:
        loaded = load_calibration(card)
        check_card_spec(loaded, spec)  # the spec's own threshold, if any, is the card's
        check_card_monitor(loaded, monitor)
        if segmenter is not None:
            loaded.check_network(segmenter)


def is_deployed(spec: str | None) -> bool:
    """Whether ``spec`` names the deployed configuration (:data:`DEPLOYED_MONITOR`), however it is written."""
    try:
        parsed = parse_monitor_spec(spec)
    except ValueError:
        return False
    return parsed is not None and parsed.name == parse_monitor_spec(DEPLOYED_MONITOR).name


def calibrated_spec(monitor: str | None, calibration: str | None) -> str | None:
    """The monitor spec to run: ``monitor``, or the card's calibrated spec (which must calibrate ``monitor``, and
    equal it where ``monitor`` carries a threshold)."""
    if not calibration:
        return monitor

    card = load_calibration(calibration)
    check_card_spec(card, monitor)  # the card's monitor, at no threshold of its own or at the card's
    return card.spec


def decide(image: np.ndarray | str | Path, config: PipelineConfig | None = None, *, pose: Pose | None = None,
           **kwargs: Any) -> Decision:
    """One-shot convenience: build an ``EmergencyLanding`` and decide for one frame; never raises."""
    return EmergencyLanding(config, **kwargs).decide(image, pose=pose)


__all__ = [
    "DEFAULT_TIME_BUDGET_S",
    "Disc",
    "EmergencyLanding",
    "FrameFile",
    "PipelineConfig",
    "decide",
]
