"""Work stops at the deadline: an ONNX Runtime run in flight when the decision's time budget passes is
cancelled (``RunOptions.terminate``, set from the deadline's timer or the hard stop), so the decision ends as
``timeout`` promptly instead of computing on in the background; torch, which cannot be cancelled mid-pass, starts
no further pass after the deadline. Decisions within their budget are those without one.

The timing assertions are loose on purpose (a busy shared CPU): what is asserted is that cancellation happened
(the session saw its run's ``terminate`` flag) and the reason, not tight wall-clock numbers."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np
import pytest
import torch
from helpers import FakeClock, OracleSegmenter, scene_ids, scene_image

import el.base.deadline as dl
from el.base.errors import BudgetExceeded
from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig

pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from onnx_helpers import ColourNet, noisy_colours  # noqa: E402

from assurance.fitting.network.onnx_export import export_onnx  # noqa: E402
from el.segmentation.inference import Segmenter  # noqa: E402
from el.segmentation.onnx_engine import OnnxEngine  # noqa: E402
from el.segmentation.onnx_model import load_onnx_model  # noqa: E402
from el.segmentation.patch_pool import PatchPool  # noqa: E402

WW = 128
FRAME = noisy_colours(scene_ids(256, 144, seed=3))
STALL_S = 30.0  # a stalled run's own limit: far past any deadline here (a run never cancelled fails the test)


class Stalling:
    """An ONNX Runtime session whose runs with run options stall until their ``terminate`` flag is set, then hand
    the run to the real session with those options (which refuses it, as ONNX Runtime does a cancelled run): a
    network far slower than its budget. ``saw_terminate``: how many runs were cancelled; ``plain``: runs given no
    options (outside a decision) go straight through."""

    def __init__(self, inner, stall: bool = True) -> None:
        self.inner, self.stall = inner, stall
        self.saw_terminate = 0
        self.options: list = []
        self.lock = threading.Lock()

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def run(self, names, feeds, run_options=None):
        with self.lock:
            self.options.append(run_options)
        if run_options is None or not self.stall:
            return self.inner.run(names, feeds, run_options)
        end = time.perf_counter() + STALL_S
        while not run_options.terminate and time.perf_counter() < end:
            time.sleep(0.002)
        if run_options.terminate:
            with self.lock:
                self.saw_terminate += 1
        return self.inner.run(names, feeds, run_options)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    native = Segmenter(ColourNet(), working_width=WW, card={"weights_sha256": "ab" * 32}, labels=UAVID)
    path = tmp_path_factory.mktemp("onnx") / "colour.onnx"
    result = export_onnx(native, path, frame=FRAME)
    return path, result["sha256"]


def _stopped_workers_end(timeout: float = STALL_S) -> None:
    for t in threading.enumerate():
        if t.name in ("uav-el-decision", "uav-el-deadline"):
            t.join(timeout)


def _landing(exported, budget, *, hard_stop=True, stall=None, monitor="lhd", evaluate_all=False):
    model = load_onnx_model(exported[0], working_width=WW, labels=UAVID)
    if stall is not None:
        model._session = Stalling(model._session, stall)
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor=monitor, time_budget_s=budget,
                         hard_stop=hard_stop, evaluate_all=evaluate_all)
    return EmergencyLanding(cfg, segmenter=model), model


@pytest.mark.requirements("EL-R07")
@pytest.mark.parametrize("hard_stop", [True, False])
def test_an_onnx_run_in_flight_is_cancelled_at_the_deadline(exported, hard_stop):
    """The frame's run stalls far past a 0.05 s budget: the deadline sets its terminate flag (the hard stop's
    cancellation, or the timer armed at the remaining budget without it), the run ends, the decision is the
    default action for 'timeout', and decide() returns long before the stalled run's own limit."""
    landing, model = _landing(exported, 0.05, hard_stop=hard_stop, stall=True)
    t0 = time.perf_counter()
    d = landing.decide(FRAME)
    returned = time.perf_counter() - t0
    _stopped_workers_end()
    assert (d.action, d.reason) == ("default", "timeout")
    assert model._session.saw_terminate == 1  # the one run in flight was cancelled, no later run started
    assert len(model._session.options) == 1 and model._session.options[0].terminate
    assert returned < STALL_S / 3  # not the stalled run's end: cancelled (loose: a busy CPU)
    assert landing._lock.acquire(timeout=STALL_S / 3)  # the stopped decision has ended: its work stopped
    landing._lock.release()


def test_decisions_within_the_budget_are_the_uncancelled_ones(exported):
    """Runs armed with a deadline that does not pass give the numbers of plain runs: with a budget of 1000 s
    the decision (reason, selected disc, every candidate and its verdict and score) is the one with no budget, and no
    run was cancelled."""
    image = noisy_colours(scene_ids(256, 144, seed=5))
    decisions, sessions = [], []
    for budget in (None, 1000.0):
        landing, model = _landing(exported, budget, stall=False, evaluate_all=True)
        decisions.append(landing.decide(image))
        sessions.append(model._session)
    plain, budgeted = decisions
    assert budgeted.reason == plain.reason and budgeted.selected == plain.selected
    assert len(plain.candidates) >= 1
    assert [(replace(c, monitor=None), c.monitor.accepted, c.monitor.score) for c in budgeted.candidates] == \
        [(replace(c, monitor=None), c.monitor.accepted, c.monitor.score) for c in plain.candidates]
    for session in sessions:
        assert session.options and not any(o is not None and o.terminate for o in session.options)


def test_a_run_outside_a_decision_is_plain(exported):
    """With no active deadline (a campaign, a probe) the run gets no options and nothing is armed."""
    model = load_onnx_model(exported[0], working_width=WW, labels=UAVID)
    session = model._session = Stalling(model._session)
    model.predict_frame(FRAME)
    assert session.options == [None]


def test_patch_pool_runs_in_flight_are_all_cancelled(exported):
    """Patches side by side on the pool's sessions (the shipped network's ONNX engine): at the deadline every run
    in flight is cancelled, and the call raises BudgetExceeded (the decision's 'timeout')."""
    path, sha = exported
    engine = OnnxEngine(path, sha, 1)
    seg = Segmenter(ColourNet(), working_width=WW, labels=UAVID, engine=engine)
    seg.patch_workers = 2
    stalled: list[Stalling] = []

    def make() -> OnnxEngine:
        e = OnnxEngine(path, sha, 1)
        e._session = Stalling(e._session)
        stalled.append(e._session)
        return e

    seg._pool = PatchPool(make, 2)
    patches = [np.ascontiguousarray(FRAME[y:y + 40, x:x + 48]) for y, x in ((0, 0), (50, 60), (90, 100), (20, 180))]
    with dl.active(dl.Deadline(time.perf_counter, 0.05)), pytest.raises(BudgetExceeded):
        seg.predict_patches(patches)
    assert [s.saw_terminate for s in stalled] == [1, 1]  # one run in flight on each worker, both cancelled


def test_the_stop_acts_only_past_the_deadline_and_only_during_its_step():
    """``Deadline.stopping``: its stop is called by the timer after the deadline (the clock then past it), by
    ``cancel`` while the step runs, never once the step has ended, never by time on an injected clock; a step
    does not start past the deadline."""
    calls: list[bool] = []
    deadline = dl.Deadline(time.perf_counter, 0.05)
    done = threading.Event()
    with deadline.stopping(lambda: (calls.append(deadline.expired()), done.set()), "a step"):
        assert done.wait(STALL_S)
    assert calls == [True]

    calls.clear()
    quick = dl.Deadline(time.perf_counter, 0.05)
    with quick.stopping(lambda: calls.append(True), "a quick step"):
        pass
    time.sleep(0.1)  # past the deadline: the step's timer was cancelled with the step
    assert calls == [] and quick.expired()
    with pytest.raises(BudgetExceeded, match="during a late step"), quick.stopping(lambda: None, "a late step"):
        pass

    fake = dl.Deadline(FakeClock(), 0.01)  # injected seconds are not a timer's: only the cooperative checks
    with fake.stopping(lambda: calls.append(True), "a step on a fake clock"):
        time.sleep(0.05)
    assert calls == []
    unbudgeted = dl.Deadline(time.perf_counter, None)
    with unbudgeted.stopping(lambda: calls.append(True), "a step"):
        unbudgeted.cancel()  # the hard stop
    assert calls == [True]


@pytest.mark.usefixtures("one_torch_thread")
def test_torch_starts_no_pass_after_the_deadline():
    """Torch cannot cancel a forward pass: the one in flight at the deadline runs to its end (the remaining worst
    case), then no further pass starts (the patches' checkpoint), and the decision is 'timeout'."""
    torch.manual_seed(0)
    passes: list[float] = []

    class Slow(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.net = ColourNet()

        def forward(self, x):
            passes.append(time.perf_counter())
            time.sleep(0.3)
            return self.net(x)

    seg = Segmenter(Slow(), working_width=WW, labels=UAVID)
    seg.predict_frame = OracleSegmenter(WW).predict_frame  # the frame at once: candidates, then patches
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", time_budget_s=0.2, hard_stop=False)
    t0 = time.perf_counter()
    d = EmergencyLanding(cfg, segmenter=seg).decide(scene_image(scene_ids()))
    assert (d.action, d.reason) == ("default", "timeout")
    assert len(passes) <= 1 and all(p - t0 < 0.2 + 0.05 for p in passes)  # none started after the deadline
