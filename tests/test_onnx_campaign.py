"""An ONNX network in campaigns and in flight: the manifest names its file, monitors needing the network's
inside are refused before anything runs, and (the ONNX worked example) the same campaign natively and
through the ONNX export gives the same decisions."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from helpers import scene_ids  # noqa: E402
from onnx_helpers import ColourNet, noisy_colours  # noqa: E402

from assurance.campaign import readouts  # noqa: E402
from assurance.campaign.run import CampaignConfig, Execution, run_campaign  # noqa: E402
from assurance.dataio.uavid import write_sample  # noqa: E402
from assurance.fitting.network.onnx_export import export_onnx  # noqa: E402
from el.base.hashing import sha256_file  # noqa: E402
from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig  # noqa: E402
from el.geometry.config import CoreConfig  # noqa: E402
from el.monitors import build_monitor  # noqa: E402
from el.monitors.capabilities import check_monitor_capabilities, required_capabilities  # noqa: E402
from el.segmentation.contract import MC_DROPOUT  # noqa: E402
from el.segmentation.inference import Segmenter  # noqa: E402
from el.segmentation.onnx_model import load_onnx_model  # noqa: E402

W, H = 1024, 576  # the working resolution: no resampling, so no colour exactly between two classes
MONITORS = ("lhd", "lhd+ch:tau=0.25")
MCD = "lhd+mcd:n=10,rho=0.9"
HAZARD_TOLERANCE = 1e-5  # predicted hazards of the two engines (float32 rounding of the same network)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("scenes")
    for i in range(2):
        ids = scene_ids(W, H, seed=i, road_col=160 + 300 * i)
        write_sample(root, "seq00", f"{i:06d}", noisy_colours(ids, seed=i), ids, labels=UAVID)
    return root


@pytest.fixture(scope="module")
def native():
    return Segmenter(ColourNet(), working_width=1024, labels=UAVID)


@pytest.fixture(scope="module")
def onnx_file(native, tmp_path_factory):
    path = tmp_path_factory.mktemp("onnx") / "colour.onnx"
    export_onnx(native, path, frame=noisy_colours(scene_ids(W, H, seed=5)))
    return path


def config(weights=None, monitors=MONITORS):
    return CampaignConfig(perturbations=("none", "fog"), monitors=monitors, weights=weights,
                          core=CoreConfig(n_star=6))


@pytest.fixture(scope="module")
def runs(data, native, onnx_file, tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    a = run_campaign(data, root / "native", config(), segmenter=native, execution=Execution(progress=False))
    b = run_campaign(data, root / "onnx", config(str(onnx_file)),
                     execution=Execution(progress=False))  # loaded by the campaign
    assert a["faults"] == [] and b["faults"] == [] and a["done"] == b["done"] == 4
    return root / "native", root / "onnx"


def test_the_manifest_names_the_onnx_file(runs, onnx_file):
    weights = json.loads((runs[1] / "manifest.json").read_text())["weights"]
    assert weights["sha256"] == sha256_file(onnx_file) and weights["path"] == str(onnx_file)
    assert weights["format"] == "onnx" and weights["contract"]["class_names"][0] == "clutter"


def test_native_and_onnx_campaigns_decide_alike(runs):
    """Worked example 1: the same decision on every frame (action, reason, selected rank), true hazards of the
    default area, top candidate and decision within HAZARD_TOLERANCE; on the clean frames every candidate alike.

    Fog mixes every colour with grey, which puts some pixels of this colour classifier within float rounding
    of a tie between two classes: there a pixel may flip, the K-means representatives move by a few pixels,
    and candidate rows are compared on the clean frames only (the decisions on all)."""
    keys = ["key", "perturbation", "severity", "monitor"]
    a, b = (readouts.load_table(r, "images").sort_values(keys).reset_index(drop=True) for r in runs)
    assert len(a) == len(b) == 8 and (a["candidates"] > 0).all() and (a["action"] == "land").any()
    for col in ("action", "reason", "selected"):
        pd.testing.assert_series_equal(a[col], b[col], check_names=False)
    for col in ("h_default", "h_top", "h_decision"):
        assert np.abs(a[col] - b[col]).max() <= HAZARD_TOLERANCE
    ckeys = [*keys, "rank"]
    ca, cb = (readouts.load_table(r, "candidates").query("perturbation == 'none'").sort_values(ckeys)
              .reset_index(drop=True) for r in runs)
    assert len(ca) == len(cb) > 0
    for col in ("x", "y", "radius_px", "accepted", "selected", "examined", "true_hazard"):
        pd.testing.assert_series_equal(ca[col], cb[col], check_names=False)
    for col in ("hazard", "score"):
        assert np.abs(ca[col] - cb[col]).max() <= HAZARD_TOLERANCE


def test_mc_dropout_configuration_is_refused_before_the_run(data, onnx_file, tmp_path):
    model = load_onnx_model(onnx_file)
    assert required_capabilities(build_monitor(MCD, labels=UAVID)) == (MC_DROPOUT,)
    assert required_capabilities(build_monitor("lhd", labels=UAVID)) == () == \
        required_capabilities(build_monitor("learned", labels=UAVID))
    with pytest.raises(ValueError, match=r"monitor 'lhd\+mcd:n=10,rho=0.9' needs MC dropout") as err:
        check_monitor_capabilities(build_monitor(MCD, labels=UAVID), model)
    assert "\n" not in str(err.value) and "colour.onnx" in str(err.value)
    with pytest.raises(ValueError, match="needs MC dropout"):
        run_campaign(data, tmp_path / "run", config(str(onnx_file), (*MONITORS, MCD)),
                     execution=Execution(progress=False))
    assert not (tmp_path / "run").exists()  # refused before the run folder, never a fault per task


def test_the_pipeline_refuses_mc_dropout_on_an_onnx_model(onnx_file):
    frame = noisy_colours(scene_ids(W, H, seed=1))
    refused = EmergencyLanding(PipelineConfig(monitor=MCD), weights=onnx_file)
    decision = refused.decide(frame)
    assert decision.action == "default" and decision.reason.startswith("fault: monitor: MonitorSupportError")
    assert "needs MC dropout" in decision.reason
    flies = EmergencyLanding(PipelineConfig(monitor="lhd"), weights=onnx_file)
    assert flies.fault is None and flies.decide(frame).reason in ("accepted", "all_rejected", "no_candidate")
