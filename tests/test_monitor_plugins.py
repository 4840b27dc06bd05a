"""Monitor plugins: a package outside the repository adds a monitor through the ``uav_el.monitors``
entry points, and it works by name in ``uav-el land``, the pipeline and a campaign."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import OracleSegmenter, bench_system, install_distribution, scene_ids

from assurance.dataio.uavid import write_image, write_sample
from el.classes.labels import UAVID, ids_to_colors
from el.monitors import build_monitor, monitor_names, parse_monitor_spec, registry

PLUGIN = Path(__file__).parent / "plugins" / "toy_uav_monitor.py"


@pytest.fixture
def toy_installed(tmp_path, monkeypatch):
    """The toy monitor as an installed distribution: its module and a dist-info with the entry point."""
    site = tmp_path / "site"
    install_distribution(site, PLUGIN, registry.ENTRY_POINT_GROUP, "toy = toy_uav_monitor:ToyMonitor")
    monkeypatch.syspath_prepend(str(site))
    registry.reload_plugins()
    yield
    sys.modules.pop("toy_uav_monitor", None)
    registry.reload_plugins()


def test_entry_point_monitor_is_found_parsed_and_built(toy_installed):
    assert "toy" in monitor_names()
    spec = parse_monitor_spec("TOY: q=0.9, threshold=0.25")
    assert spec.name == "toy:q=0.9,threshold=0.25"
    m = build_monitor(spec, labels=UAVID)
    assert (m.q, m.threshold, m.name) == (0.9, 0.25, "toy:q=0.9,threshold=0.25")
    assert build_monitor("toy", labels=UAVID).name == "toy:q=1.0"
    mask = np.ones((2, 2), bool)
    scores = np.zeros((8, 2, 2), np.float32)
    scores[5] = 1.0
    scores[:, 0, 0] = 0.0
    scores[2, 0, 0] = 1.0  # one road pixel in four
    v = build_monitor("toy", labels=UAVID).check_scores(scores, mask)
    assert (v.accepted, v.score, v.threshold) == (False, 1.0, 0.5)
    v = build_monitor("toy:q=0.5", labels=UAVID).check_scores(scores, mask)
    assert v.accepted and v.score == 0.0
    for bad, needle in (("toy:q=x", "could not convert"), ("toy:z=1", "takes no parameter 'z'"),
                        ("toy:q=2", "q must lie")):
        with pytest.raises(ValueError, match=needle):
            build_monitor(bad, labels=UAVID)


def test_unknown_and_broken_plugins_fail_loud(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="unknown monitor 'nosuch'.*registered: lhd"):
        parse_monitor_spec("nosuch")
    site = tmp_path / "site"
    info = site / "broken-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{registry.ENTRY_POINT_GROUP}]\nbroken = no_such_module:X\n")
    monkeypatch.syspath_prepend(str(site))
    registry.reload_plugins()
    try:
        with pytest.raises(ValueError, match="plugin 'broken'.*failed to load: ModuleNotFoundError"):
            parse_monitor_spec("broken")
        parse_monitor_spec("lhd")  # the others still work
    finally:
        registry.reload_plugins()


def test_land_and_campaign_run_the_plugin_monitor_by_name(toy_installed, tmp_path, capsys, monkeypatch):
    import torch

    from assurance import cli
    from assurance.campaign.readouts import load_table
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign
    from assurance.fitting.network.weights_io import save_weights
    from el.geometry.config import CoreConfig
    from el.segmentation.architectures import build_model
    from el.segmentation.model import ArchConfig

    torch.manual_seed(0)
    weights = tmp_path / "tiny.pt"
    save_weights(build_model(ArchConfig(widths=(8, 8, 8), ms_channels=8, decoder_channels=8)), weights)
    ids = scene_ids(256, 144, seed=1)
    image = tmp_path / "frame.png"
    write_image(image, ids_to_colors(ids))
    out = tmp_path / "d.json"
    monkeypatch.setattr(cli, "COMMANDS", {"land": "land"})
    monkeypatch.chdir(bench_system(tmp_path / "bench").parent)  # the test frame is smaller than the default's 4K
    code = cli.main(["land", str(image), "--weights", str(weights), "--monitor", "toy:q=0.9", "--all",
                     "--budget", "1000", "--working-width", "1024", "--json", str(out)])
    assert code == 0, capsys.readouterr().err
    d = json.loads(out.read_text())
    assert d["config"]["monitor"] == "toy:q=0.9" and d["reason"] != "timeout"
    verdicts = [c["monitor"] for c in d["candidates"]]
    assert verdicts and all(v["name"] == "toy:q=0.9" and v["threshold"] == 0.5 for v in verdicts)
    assert all(v["accepted"] == (not v["score"] > 0.5) for v in verdicts)

    data = tmp_path / "data"
    for i in range(2):
        s = scene_ids(256, 144, seed=i, road_col=60 + 90 * i)
        write_sample(data, "seq00", f"{i:06d}", ids_to_colors(s), s, labels=UAVID)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd", "toy:q=0.9,threshold=0.1"),
                            core=CoreConfig(n_star=6, working_width=128), weights=str(weights))
    summary = run_campaign(data, tmp_path / "run", config, segmenter=OracleSegmenter(128),
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    cands = load_table(tmp_path / "run", "candidates")
    toy = cands[cands["monitor"] == "toy:q=0.9,threshold=0.1"]
    assert len(toy) and len(toy) == (cands["monitor"] == "lhd").sum()
    assert (toy["threshold"] == 0.1).all() and (toy["accepted"] == ~(toy["score"] > 0.1)).all()
