"""What a campaign assesses is what flies: one campaign task and ``EmergencyLanding.decide`` run the same kernel
(``el.flight.kernel``), so on the same frames (the frame gate firing on some, frames outside the declared domain, a
timeout) the campaign's decision of each configuration is flight's: the same action, selected candidate and
reason."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import TINY_ARCH, FakeClock, TappedOracle, write_textured_scenes

from assurance.campaign.run import CampaignConfig, plan, run_task, task_seed
from assurance.campaign.task import frame_identity
from assurance.dataio.uavid import read_image
from assurance.perturbations import perturb
from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.geometry.odd import OperatingDomain
from el.monitors.frame_gate import frame_gate_document, load_frame_gate

W, H, WW = 128, 72, 64
SHA = "7e" * 32
MONITORS = ("lhd", "lhd+ch:tau=0.25")
BUDGET = 5.0


class SlowOn:
    """The tiny network, with a forward pass that takes (by the injected clock) longer than the budget on some
    frames: the deadline must stop those frames the same way in flight and in the campaign."""

    def __init__(self, seg, clock: FakeClock, slow: set[int]) -> None:
        self.__dict__.update(seg=seg, clock=clock, slow=slow)

    def __getattr__(self, name):
        return getattr(self.seg, name)

    def __setattr__(self, name, value):
        setattr(self.seg, name, value)

    def predict_frame(self, rgb, **kwargs):
        if int(rgb[0, 0, 0]) in self.slow:
            self.clock.t += 2 * BUDGET
        return self.seg.predict_frame(rgb, **kwargs)


@pytest.fixture(scope="module")
def world(tmp_path_factory, one_torch_thread):
    import torch

    from assurance.fitting.frame_gate_fit import GateSettings, fit_gate
    from el.segmentation.architectures import build_model
    from el.segmentation.inference import Segmenter

    root = tmp_path_factory.mktemp("kernel")
    train, val = write_textured_scenes(root / "train", range(20)), write_textured_scenes(root / "val", range(40, 46))
    write_textured_scenes(root / "data", range(100, 108))
    write_textured_scenes(root / "data", range(200, 204), 96, 54, sequence="seq01")  # outside the frame size
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH), working_width=WW, card={"weights_sha256": SHA}, labels=UAVID)
    doc = fit_gate(train, val, seg, settings=GateSettings(kind="mahalanobis", quantile=0.99), val_scenes="0:6",
                   weights={"path": None, "sha256": SHA, "segmenter": "weights"})
    gate = load_frame_gate(_write(root / "fitted.json", doc))
    # a threshold inside the campaign frames' scores, so that the gate refuses some of them and passes others
    scores = []
    for p in sorted((root / "data" / "seq00").glob("Images/*.png")):
        scores.append(gate.score(seg.predict_frame(read_image(p), stats=True).stats))
    body = dict(doc["body"])
    body["threshold"] = float(np.median(scores))
    path = _write(root / "gate.json", frame_gate_document(body))
    odd = OperatingDomain.from_dict({"height_m": [40, 60], "pitch_deg": [36, 54], "image_width": [120, 130],
                                     "image_height": [60, 80], "aspect": [1.5, 2.0]})
    return {"root": root, "seg": TappedOracle(seg, WW, SHA),
            "gate": {"path": str(path), "sha256": load_frame_gate(path).sha256}, "odd": odd}


def _write(path, doc):
    path.write_text(json.dumps(doc), "utf-8")
    return path


def _campaign(world, clock, slow, budget=BUDGET):
    config = CampaignConfig(perturbations=("none", "motion_blur"), monitors=MONITORS,
                            core=CoreConfig(working_width=WW), odd=world["odd"].to_dict(), gate=world["gate"],
                            time_budget_s=budget)
    segmenter = SlowOn(world["seg"], clock, slow)
    return config, segmenter, [(t, run_task(t, config, segmenter, clock=clock)) for t in plan(world["root"] / "data",
                                                                                             config)]


def _slow_marks(world):
    """Two of the in-domain frames are slow: their top-left red value under the 'none' perturbation."""
    frames = sorted((world["root"] / "data" / "seq00").glob("Images/*.png"))
    return {int(read_image(p)[0, 0, 0]) for p in frames[:2]}


def _compare(world, *, budget=BUDGET):
    """(mismatches, flight's reasons): every campaign decision of each configuration against flight's."""
    clock = FakeClock()
    config, segmenter, tasks = _campaign(world, clock, _slow_marks(world), budget)
    mismatches, reasons = [], []
    for monitor in MONITORS:
        system = EmergencyLanding(PipelineConfig(core=config.core, monitor=monitor, time_budget_s=BUDGET,
                                                 odd=world["odd"], gate=world["gate"]["path"]),
                                  segmenter=segmenter, clock=clock)
        assert system.fault is None
        for task, rows in tasks:
            row = next(r for r in rows["images"] if r["monitor"] == config.monitors[MONITORS.index(monitor)])
            assert not row["fault"], row
            rgb = read_image(task.sample.image_path)
            rng = np.random.default_rng(task_seed(config.seed, frame_identity(rgb), task.perturbation, task.severity))
            frame = perturb(rgb, task.perturbation, task.severity, rng)
            decision = system.decide(frame)
            flight = (decision.action, -1 if decision.selected is None else decision.selected, decision.reason)
            if (row["action"], row["selected"], row["reason"]) != flight:
                mismatches.append((task.shard_name, monitor, row["reason"], decision.reason))
            reasons.append(decision.reason)
    return mismatches, reasons


def test_a_campaign_decides_every_frame_as_flight_does(world):
    mismatches, reasons = _compare(world)
    assert not mismatches
    # the cases the comparison covers, each seen at least once
    assert any(r.startswith("outside_odd") for r in reasons)
    assert any(r.startswith("out_of_domain: frame gate") for r in reasons)
    assert "timeout" in reasons
    assert reasons.count("accepted") >= 4  # frames landed on, after a walk


@pytest.mark.parametrize("skip", ["gate", "domain", "deadline"])
def test_the_comparison_fails_on_a_campaign_that_skips_a_deployed_part(skip, world, monkeypatch):
    """The comparison above catches a campaign that leaves out the deployed gate, the declared domain or the
    deadline (as the campaign's own copy of the decision did before the kernel: it had no deadline)."""
    from dataclasses import replace

    import assurance.campaign.task as task

    parts = task.task_parts
    if skip in ("gate", "domain"):
        field = {"gate": "gate", "domain": "odd"}[skip]
        monkeypatch.setattr(task, "task_parts", lambda *a: replace(parts(*a), **{field: None}))
    mismatches, _ = _compare(world, budget=None if skip == "deadline" else BUDGET)
    assert mismatches
    want = {"gate": "out_of_domain", "domain": "outside_odd", "deadline": "timeout"}[skip]
    assert all(flight.startswith(want) for *_, flight in mismatches), mismatches


def test_monitor_coverage_holds_where_the_gate_and_the_domain_refuse_frames(world):
    """EL-R04 judges what flies: a frame refused by the declared domain or the frame gate keeps its candidates'
    verdicts in the readouts (some accepted) and is the default action by design, not a coverage breach."""
    import pandas as pd

    from assurance.requirements.checks import check_monitor_coverage

    _, _, tasks = _campaign(world, FakeClock(), set(), None)
    images = pd.DataFrame([r for _, rows in tasks for r in rows["images"]])
    candidates = pd.DataFrame([r for _, rows in tasks for r in rows["candidates"]])
    refused = images[images["reason"].str.startswith(("out_of_domain", "outside_odd"))]
    keys = set(zip(refused["key"], refused["perturbation"], refused["monitor"], strict=True))
    accepted = candidates[candidates["accepted"].astype(bool)]
    assert any(k in keys for k in zip(accepted["key"], accepted["perturbation"], accepted["monitor"], strict=True))
    evidence = check_monitor_coverage(images, candidates)
    assert evidence.status == "pass", evidence.message()


def test_one_place_builds_the_kernel_s_parts():
    """Flight, the campaign task and the ground truth get their ``Parts`` from ``el.flight.kernel.build_parts`` (the
    label
    set from the network, the gate bound to it): no other module constructs them."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    makers = {str(p.relative_to(root)) for folder in ("el", "assurance") for p in (root / folder).rglob("*.py")
              if re.search(r"(?<![\w.])Parts\(", p.read_text("utf-8"))}
    assert makers == {"el/flight/kernel.py"}, makers
    users = {"el/flight/pipeline.py", "assurance/campaign/task.py", "assurance/campaign/gt_pipeline.py"}
    assert all("build_parts(" in (root / u).read_text("utf-8") for u in users)
