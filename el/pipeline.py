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
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from el.camera import Pose, check_geometry
from el.config import CoreConfig, check_seed
from el.core import default_area, run_core
from el.deadline import Deadline, active, run_with_deadline
from el.decision import Candidate, Decision, Disc, MonitorVerdict
from el.errors import BudgetExceeded
from el.hashing import sha256_bytes
from el.imageio import MAX_PIXELS, check_max_pixels, read_image_meta
from el.labels import UAVID
from el.monitors import CandidateContext, Monitor, build_monitor, monitor_name, parse_monitor_spec
from el.monitors.capabilities import check_monitor_capabilities
from el.monitors.frame_gate import bind_frame_gate, judge_frame
from el.odd import OperatingDomain
from el.rgb import check_rgb
from el.segmentation.contract import check_model, labels_of
from el.walk import HAZARD, WalkOutcome, walk_candidates

Clock = Callable[[], float]
DEFAULT_TIME_BUDGET_S = 10.0
DEPLOYED_MONITOR = "learned:walk=score,threshold=0.8563253044730293"
"""The shipped runtime monitor, chosen on the validation split (README, "The deployed monitor"): the learned
candidate monitor (``el/monitors/data/learned.json``), candidates walked by its score (``el.walk``),
at the threshold of its calibration card :data:`DEPLOYED_CALIBRATION` (a test checks they agree)."""
DEPLOYED_CALIBRATION = Path(__file__).resolve().parent / "monitors" / "data" / "calibration.json"
DEPLOYED_GATE: Path | None = Path(__file__).resolve().parent / "monitors" / "data" / "frame_gate.json"
"""The frame gate the command line deploys when it runs the shipped network (None: none): a Mahalanobis gate on the
frame pass's trunk statistics, fitted and thresholded on 3840x2160 training and validation frames under the
in-domain perturbations (README, "Frame gates"). ``PipelineConfig.gate`` is what the flight code deploys; the
command line sets it to this unless ``--gate``/``[monitor] gate`` say otherwise."""
MIN_FRAME_SIZE = 16  # px: the smallest frame side the segmenter takes (el.segmentation.inference.MIN_SIZE)
logger = logging.getLogger(__name__)  # faults with their tracebacks; the decision keeps only the reason


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
        checkpoint (``el.deadline``). False, or an injected clock: the cooperative checks alone.
    max_pixels : int
        Largest frame accepted, in pixels (:data:`el.imageio.MAX_PIXELS`, 8K plus a quarter by default): a file
        whose header claims more is refused before decoding (default action, the reason naming the file).
    ood : path or None
        An out-of-domain gate (``uav-el fit-ood``, ``el.monitors.ood``): a frame whose distance is above
        the gate's threshold ends in the default action with reason ``out_of_domain``; a missing or
        altered gate file is a fault (default action).
    gate : path or None
        A frame gate (``uav-el fit-gate``, ``el.monitors.frame_gate``) scoring the frame pass's own statistics: a
        frame above its threshold ends in the default action (``out_of_domain: frame gate ...``); its score and
        threshold are in every decision's ``input.frame_gate`` (null: no gate). A bad gate file is a fault.
    odd : OperatingDomain or None
        The declared operating domain (``el.odd``): a frame whose pose or size is outside it ends in the
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
    ood: str | None = None
    gate: str | None = None
    odd: OperatingDomain | None = None
    max_pixels: int = MAX_PIXELS
    hard_stop: bool = True

    def __post_init__(self) -> None:
        parse_monitor_spec(self.monitor)  # a bad spec fails here, before any image
        check_max_pixels(self.max_pixels)
        if self.time_budget_s is not None and not (math.isfinite(self.time_budget_s) and self.time_budget_s > 0):
            raise ValueError(f"time_budget_s must be a positive number of seconds or None, got {self.time_budget_s!r}")
        check_seed(self.seed)
        if self.odd is not None and not isinstance(self.odd, OperatingDomain):
            raise ValueError(f"odd must be an el.odd.OperatingDomain or None, got {type(self.odd).__name__}")

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
            **({"ood": self.ood} if self.ood else {}),
            **({"gate": self.gate} if self.gate else {}),
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
    ) -> None:
        self.config = config or PipelineConfig()
        self.clock = clock
        self._lock = threading.Lock()
        self.fault: str | None = None
        self.segmenter = segmenter
        self.monitor: Monitor | None = None
        self.walk = HAZARD
        self.ood: Any = None
        self.gate: Any = None
        self.labels = UAVID
        try:
            if segmenter is None:
                from el.segmentation.factory import load_model

                self.segmenter = load_model(weights, working_width=self.config.core.working_width)
            else:
                check_model(segmenter)
            self.labels = labels_of(self.segmenter)  # the system's label set is the one its network segments into
        except Exception as exc:  # missing/altered weights: every decision is the default action
            self.fault = f"fault: model: {type(exc).__name__}: {exc}"
            logger.exception("segmentation model not loaded; every decision will be the default action")
        try:
            spec = calibrated_spec(self.config.monitor, self.config.calibration)
            self.walk = getattr(parse_monitor_spec(spec), "walk", HAZARD)
            self.monitor = build_monitor(
                spec, margin=self.config.patch_margin,
                max_side=self.config.patch_max_side, clock=clock, labels=self.labels,
            )
            check_monitor_bindings(self.monitor, spec, self.config.calibration, self.segmenter)
        except Exception as exc:
            self.fault = self.fault or f"fault: monitor: {type(exc).__name__}: {exc}"
            logger.exception("runtime monitor %r not built; every decision will be the default action",
                             self.config.monitor)
        if self.config.ood:
            try:
                from el.monitors.ood import load_ood

                self.ood = load_ood(self.config.ood)
                self.ood.check_network(self.segmenter)
                check_monitor_capabilities(None, self.segmenter, ood=self.ood)
            except Exception as exc:
                self.fault = self.fault or f"fault: ood: {type(exc).__name__}: {exc}"
                logger.exception("out-of-domain gate not usable; every decision will be the default action")
        if self.config.gate:
            try:
                self.gate = bind_frame_gate(self.config.gate, self.segmenter)
            except Exception as exc:
                self.fault = self.fault or f"fault: frame_gate: {type(exc).__name__}: {exc}"
                logger.exception("frame gate not usable; every decision will be the default action")

    # -- the decision ----------------------------------------------------------------------------
    def decide(self, image: np.ndarray | str | Path, pose: Pose | None = None) -> Decision:
        """Decide where to land for one frame (an RGB uint8 array or an image file); never raises.

        ``pose``: the camera's height and pitch when the frame was taken (from the flight log); None is
        the configured nominal pose (``config.core.pose``). It sets the safety radius in pixels and is
        recorded in the decision's ``input.pose``. (The ground-truth pipeline, with a label map instead
        of the model, is ``assurance.campaign.gt_pipeline``.)
        """
        cfg = self.config
        budget = Deadline(self.clock, cfg.time_budget_s)
        timings: dict[str, float] = {}
        info: dict[str, Any] = {}
        if not (cfg.hard_stop and cfg.time_budget_s is not None and self.clock is time.perf_counter):
            with active(budget):
                return self._decide(image, pose, budget, timings, info)

        def locked() -> Decision:  # one decision at a time: a stopped one ends at its next checkpoint
            with self._lock:
                return self._decide(image, pose, budget, timings, info)

        finished, decision = run_with_deadline(locked, budget)
        if finished:
            return decision
        try:  # the hard stop: the default action at the deadline, on what the stopped decision had read
            core_cfg = frame_core(cfg.core, pose)
        except Exception:
            core_cfg = cfg.core
        seen = dict(info)  # the worker sets width, then height
        size = (seen["width"], seen["height"]) if "height" in seen else cfg.nominal_size
        return self._default("timeout", [], size, dict(timings), seen, budget, core_cfg)

    def _decide(self, image: np.ndarray | str | Path, pose: Pose | None, budget: Deadline,
                timings: dict[str, float], info: dict[str, Any]) -> Decision:
        """The decision itself, with ``budget`` checked between stages and (as the active deadline) inside them."""
        cfg = self.config
        core_cfg = cfg.core
        size = cfg.nominal_size
        stage = "read"
        candidates: list[Candidate] = []
        try:
            if budget.cancelled.is_set():  # stopped while it waited for the one before it: read nothing
                raise BudgetExceeded("decision stopped before it started")
            t = self.clock()
            info["frame_gate"] = None if self.gate is None else self.gate.record(None)
            rgb = self._read(image, info)
            size = (rgb.shape[1], rgb.shape[0])
            if size[0] * size[1] > cfg.max_pixels:  # an array (a file was checked from its header)
                raise ValueError(f"{info['path']}: image of {size[0]}x{size[1]} pixels exceeds the limit of "
                                 f"{cfg.max_pixels} pixels (max_pixels)")
            timings["read_s"] = self.clock() - t
            stage = "pose"
            core_cfg = frame_core(cfg.core, pose)
            info["pose"] = pose_record(core_cfg.pose, nominal=pose is None)
            if self.fault:
                return self._default(self.fault, candidates, size, timings, info, budget, core_cfg)
            outside = None if cfg.odd is None else cfg.odd.outside(core_cfg.pose, size)
            if outside:  # no evidence of safety there: the default action, a decision and not a fault
                return self._default(outside, candidates, size, timings, info, budget, core_cfg)
            check_geometry(core_cfg.geometry(*size))  # a pose the flat-ground model cannot plan with: a fault
            budget.check(stage)

            stage = "segmentation"
            t = self.clock()
            probs = self._segment(rgb)
            timings["segmentation_s"] = self.clock() - t
            budget.check(stage)

            if self.gate is not None:
                stage = "frame_gate"
                refused = judge_frame(self.gate, self.segmenter, info)
                if refused:  # no evidence of safety for this frame: a decision, not a fault
                    return self._default(refused, candidates, size, timings, info, budget, core_cfg)

            if self.ood is not None:
                stage = "ood"
                t = self.clock()
                info["ood_score"] = self.ood.score(self.segmenter, rgb, probs)
                info["ood_threshold"] = self.ood.threshold
                timings["ood_s"] = self.clock() - t
                if not info["ood_score"] <= self.ood.threshold:
                    return self._default("out_of_domain", candidates, size, timings, info, budget, core_cfg)
                budget.check(stage)

            stage = "candidates"
            t = self.clock()
            candidates = run_core(probs, size, core_cfg, clock=self.clock, labels=self.labels).candidates
            timings["candidates_s"] = self.clock() - t
            budget.check(stage)

            stage = "monitoring"
            t = self.clock()
            candidates, outcome = self._walk(rgb, candidates, budget, probs)
            timings["monitoring_s"] = self.clock() - t
            timings["overhead_s"] = outcome.overhead_s
            budget.check(stage)
        except BudgetExceeded:
            return self._default("timeout", candidates, size, timings, info, budget, core_cfg)
        except Exception as exc:
            reason = f"fault: {stage}: {type(exc).__name__}: {exc}"
            logger.exception("fault in stage %s of the decision (input %s); default action", stage,
                             info.get("path", "?"))
            return self._default(reason, candidates, size, timings, info, budget, core_cfg)

        if outcome.selected is None:
            return self._default(outcome.reason, candidates, size, timings, info, budget, core_cfg)
        timings["total_s"] = budget.elapsed()
        return Decision(action="land", reason=outcome.reason, selected=outcome.selected, candidates=candidates,
                        default_area=default_area(*size, core_cfg), timings=timings, input=info,
                        config=cfg.to_dict())

    # -- stages ----------------------------------------------------------------------------------
    def _read(self, image: np.ndarray | str | Path, info: dict[str, Any]) -> np.ndarray:
        if isinstance(image, str | Path):
            path = Path(image)
            info["path"] = str(path)
            rgb, meta = read_image_meta(path, max_pixels=self.config.max_pixels)
            info["sha256"] = sha256_bytes(path.read_bytes())
            info.update(meta)  # exif_orientation, when one was applied
        else:
            rgb = image
            if not isinstance(rgb, np.ndarray):
                raise ValueError(f"image must be a numpy array or a path, got {type(rgb).__name__}")
            info["path"] = "<array>"
            check_rgb(rgb, "image", min_size=0)  # shape and type now; the size once the input is recorded
            info["sha256"] = sha256_bytes(np.ascontiguousarray(rgb).tobytes())
        info["width"], info["height"] = int(rgb.shape[1]), int(rgb.shape[0])
        return check_rgb(rgb, "image", min_size=MIN_FRAME_SIZE)

    def _segment(self, rgb: np.ndarray) -> np.ndarray:
        probs = self.segmenter.predict_frame(rgb)
        if not isinstance(probs, np.ndarray) or not np.isfinite(probs).all():
            raise ValueError("segmentation returned non-finite scores")
        return probs

    def _walk(
        self, rgb: np.ndarray, candidates: list[Candidate], budget: Deadline, probs: np.ndarray | None = None
    ) -> tuple[list[Candidate], WalkOutcome]:
        """Monitor candidates with the one decision walk (``el.walk``); returns the candidates with their
        verdicts and the outcome. The budget is checked before and after each judgement of the deciding
        walk; evaluation-only judgements past the decision (``evaluate_all``) are not budgeted."""
        if self.monitor is None:  # no runtime monitor: the CM's top candidate
            return candidates, walk_candidates(len(candidates), None)
        budgeted = self.config.time_budget_s is not None
        has_chunks = hasattr(self.monitor, "between")  # MC dropout: the budget binds between its chunks too

        def before(k: int, real: bool) -> None:
            if has_chunks:
                self.monitor.between = budget.ahead if (budgeted and real) else None
            if real:
                budget.check("monitoring")

        def after(k: int, real: bool) -> None:  # the hazard walk stops as soon as its judgement overran
            if real and budgeted and self.walk == HAZARD and budget.elapsed() > self.config.time_budget_s:
                raise BudgetExceeded("time budget exceeded during monitoring")

        def judge(k: int) -> MonitorVerdict:
            cand = candidates[k]
            context = None if probs is None else CandidateContext(cand, probs, (rgb.shape[1], rgb.shape[0]))
            return self.monitor.check(rgb, cand, self.segmenter, seed=self.config.seed + k, context=context)

        outcome = walk_candidates(len(candidates), judge, self.walk, evaluate_all=self.config.evaluate_all,
                                  before=before, after=after)
        judged = [c if v is None else replace(c, monitor=v) for c, v in zip(candidates, outcome.verdicts, strict=True)]
        return judged, outcome

    def _default(
        self,
        reason: str,
        candidates: list[Candidate],
        size: tuple[int, int],
        timings: dict[str, float],
        info: dict[str, Any],
        budget: Deadline,
        core: CoreConfig,
    ) -> Decision:
        try:
            area = default_area(*size, core)
        except Exception:  # the default area of the nominal frame: the decision itself must not fail
            logger.exception("default area of a %dx%d frame failed; using the nominal %dx%d frame", *size,
                             *self.config.nominal_size)
            area = default_area(*self.config.nominal_size, core)
        timings = dict(timings)
        timings["total_s"] = budget.elapsed()
        return Decision(action="default", reason=reason, selected=None, candidates=list(candidates),
                        default_area=area, timings=timings, input=info, config=self.config.to_dict())


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
        from el.monitors.calibration import check_card_monitor, check_card_spec, load_calibration

        loaded = load_calibration(card)
        check_card_spec(loaded, spec)  # the spec's own threshold, if any, is the card's
        check_card_monitor(loaded, monitor)
        if segmenter is not None:
            loaded.check_network(segmenter)


def frame_core(core: CoreConfig, pose: Pose | None) -> CoreConfig:
    """The core configuration of one frame: the nominal one, at the frame's pose when it brings one."""
    if pose is None:
        return core
    if not isinstance(pose, Pose):
        raise ValueError(f"pose must be an el.camera.Pose, got {type(pose).__name__}")
    values = {f.name: getattr(pose, f.name) for f in fields(pose)}
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
            raise ValueError(f"pose {name} must be a number, got {value!r}")
    return replace(core, pose=Pose(**{k: float(v) for k, v in values.items()}))  # checked again, plain floats


def pose_record(pose: Pose, *, nominal: bool) -> dict[str, Any]:
    """The pose a decision was planned with, as its JSON records it (``input.pose``)."""
    return {**{f.name: getattr(pose, f.name) for f in fields(pose)}, "source": "nominal" if nominal else "frame"}


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
    from el.monitors.calibration import check_card_spec, load_calibration

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
    "PipelineConfig",
    "decide",
]
