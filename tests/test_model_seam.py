"""The segmentation-model seam: any object with ``predict_frame``/``predict_patch`` flies, built by name
through the ``uav_el.models`` entry points, and the factory refuses what it cannot build with a clear error."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from helpers import bench_system, install_distribution, scene_ids, scene_image

from assurance.dataio.uavid import write_image
from el.base.errors import WeightsError
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.segmentation import SegmentationModel, Segmenter, load_model
from el.segmentation.contract import MC_DROPOUT, PATCH_TRUNK, check_model, has_capability, labels_of
from el.segmentation.factory import ENTRY_POINT_GROUP

PLUGIN = Path(__file__).parent / "plugins" / "colour_model.py"
WW = 128


@pytest.fixture
def colour_installed(tmp_path, monkeypatch):
    """The colour model as an installed distribution: its module and a dist-info with the entry point."""
    site = tmp_path / "site"
    install_distribution(site, PLUGIN, ENTRY_POINT_GROUP, "colour = colour_model:build")
    monkeypatch.syspath_prepend(str(site))
    yield
    sys.modules.pop("colour_model", None)


def test_a_plugin_model_is_built_by_name_and_flies(colour_installed):
    model = load_model(f"colour:{WW}")
    assert isinstance(model, SegmentationModel) and not isinstance(model, Segmenter)
    assert not has_capability(model, MC_DROPOUT) and not has_capability(model, PATCH_TRUNK)
    assert labels_of(model).name == "uavid"
    d = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd"),
                         segmenter=model).decide(scene_image(scene_ids()))
    assert d.action == "land" and d.reason == "accepted"
    # a monitor that needs a capability the model lacks: refused when the pipeline is built, so every
    # decision is the default action, with the reason naming what is missing
    d = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd+mcd:n=10,rho=0.9"),
                         segmenter=model).decide(scene_image(scene_ids()))
    assert d.action == "default" and d.reason.startswith("fault: monitor: MonitorSupportError")
    assert "MC dropout" in d.reason and "ColourModel" in d.reason


def test_land_takes_a_plugin_model_by_name(colour_installed, tmp_path, capsys, monkeypatch):
    from assurance.cli import main

    monkeypatch.chdir(bench_system(tmp_path / "bench").parent)  # the test frame is smaller than the default's 4K
    image = tmp_path / "frame.png"
    write_image(image, scene_image(scene_ids()))
    out = tmp_path / "d.json"
    assert main(["land", str(image), "--weights", f"colour:{WW}", "--monitor", "lhd", "--working-width", str(WW),
                 "--json", str(out)]) == 0, capsys.readouterr().err
    assert json.loads(out.read_text())["action"] == "land"


def test_the_factory_refuses_clearly(tmp_path):
    with pytest.raises(WeightsError, match="'nosuch' is not registered in the 'uav_el.models' entry points"):
        load_model("nosuch")
    with pytest.raises(WeightsError, match="neither a .pt or .onnx file nor a registered model name"):
        load_model("no such thing!")
    with pytest.raises(WeightsError, match="nope.pt"):
        load_model(tmp_path / "nope.pt")
    with pytest.raises(ValueError, match="lacks predict_frame, predict_patch"):
        check_model(object())
    d = EmergencyLanding(PipelineConfig(monitor="lhd"), segmenter=object()).decide(scene_image(scene_ids()))
    assert d.action == "default" and d.reason.startswith("fault: model: ValueError: segmentation model object lacks")


def test_a_campaign_runs_a_plugin_model_by_name_and_records_it(colour_installed, tiny_campaign, tmp_path, capsys):
    from assurance.campaign import readouts
    from assurance.cli import main

    run = tmp_path / "run"
    argv = ["campaign", "--data", str(tiny_campaign["data"]), "--out", str(run), "--model", "colour",
            "--perturbations", "none", "--images", "2", "--monitors", "lhd", "--quiet"]
    assert main(argv) == 0, capsys.readouterr().err
    man = readouts.read_manifest(run)
    assert man["weights"]["model"] == "colour" and man["weights"]["path"] is None
    assert readouts.load_table(run, "images")["fault"].eq("").all()


def test_a_registered_name_wins_over_a_path_like_argument(colour_installed):
    from el.segmentation.factory import FILE, PLUGIN, model_kind

    assert model_kind("colour:/models/net.onnx") == PLUGIN and model_kind("C:\\models\\net.pt") == FILE
    assert model_kind("models/net.pt") == FILE and model_kind("unregistered") == PLUGIN
    with pytest.raises(WeightsError, match=r"model 'colour' \(colour_model:build\) failed to build: ValueError"):
        load_model("colour:/models/net.onnx")  # the plugin got its argument (not the weights loader)
