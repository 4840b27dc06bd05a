"""Faults turned into a default action are logged with their traceback; the reason string is unchanged."""

from __future__ import annotations

import logging

import numpy as np
from helpers import OracleSegmenter, scene_ids, scene_image

from assurance.campaign.gt_pipeline import decide_from_labels
from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig

WW = 128


class _Exploding(OracleSegmenter):
    def predict_frame(self, rgb):
        raise RuntimeError("GPU fell off")


def _records(caplog, name: str) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == name and r.levelno == logging.ERROR]


def test_segmentation_fault_is_logged_with_traceback(caplog) -> None:
    system = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd"),
                              segmenter=_Exploding(WW))
    with caplog.at_level(logging.ERROR, logger="el.flight.kernel"):
        d = system.decide(scene_image(scene_ids()))
    assert d.action == "default"
    assert d.reason == "fault: segmentation: RuntimeError: GPU fell off"  # the reason itself is unchanged
    (rec,) = _records(caplog, "el.flight.kernel")  # the one decision kernel logs every fault
    assert "segmentation" in rec.getMessage()
    assert rec.exc_info is not None and rec.exc_info[0] is RuntimeError  # the traceback is kept


def test_missing_weights_are_logged_once_at_construction(tmp_path, caplog) -> None:
    with caplog.at_level(logging.ERROR, logger="el.flight.pipeline"):
        system = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW)), weights=tmp_path / "none.pt")
    assert len(_records(caplog, "el.flight.pipeline")) == 1
    assert system.decide(scene_image(scene_ids())).reason.startswith("fault: model")


def test_ground_truth_pipeline_fault_is_logged(caplog, monkeypatch) -> None:
    import el.flight.kernel

    def broken_core(*args, **kwargs):
        raise ValueError("no candidates today")

    monkeypatch.setattr(el.flight.kernel, "run_core", broken_core)
    with caplog.at_level(logging.ERROR, logger="el.flight.kernel"):
        d = decide_from_labels(scene_ids(), config=CoreConfig(working_width=WW), labels=UAVID)
    assert d.action == "default" and d.reason == "fault: candidates: ValueError: no candidates today"
    (rec,) = _records(caplog, "el.flight.kernel")  # the ground-truth pipeline is the flight kernel
    assert rec.exc_info is not None and rec.exc_info[0] is ValueError


def test_a_good_decision_logs_nothing(caplog) -> None:
    system = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd"),
                              segmenter=OracleSegmenter(WW))
    with caplog.at_level(logging.DEBUG, logger="el"):
        d = system.decide(np.ascontiguousarray(scene_image(scene_ids())))
    assert not d.reason.startswith("fault")
    assert [r for r in caplog.records if r.name.startswith("el.")] == []
