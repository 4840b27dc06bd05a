"""Campaign runner: shards, resume after interruption, recorded faults, shared vs single-configuration runs."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
import torch
from helpers import OracleSegmenter, scene_ids

from assurance.analysis.table import results_table
from assurance.campaign import readouts
from assurance.campaign.run import CampaignConfig, Execution, plan, run_campaign
from assurance.campaign.stages import stage_table, wall_seconds
from assurance.cli import main
from assurance.dataio.uavid import read_image, write_sample
from assurance.fitting.network.weights_io import save_weights, write_card
from el.classes.labels import UAVID, ids_to_colors
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import CoreConfig
from el.segmentation.architectures import build_model
from el.segmentation.model import ArchConfig
from el.segmentation.weights import read_card

W, H = 512, 288
MONITORS = ("lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.9", "lhd+mcd:n=30,rho=0.9")
TIMING = {"overhead_s", "overhead_s_lo95", "overhead_s_hi95"}


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    torch.manual_seed(0)
    model = build_model(ArchConfig(widths=(8, 8, 8), ms_channels=8, decoder_channels=8))
    path = tmp_path_factory.mktemp("w") / "tiny.pt"
    save_weights(model, path)
    return str(path)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("scenes")
    rng = np.random.default_rng(0)
    for i in range(3):
        ids = scene_ids(W, H, seed=i, road_col=60 + 90 * i)
        img = ids_to_colors(ids).astype(np.int16) + rng.integers(-20, 20, (H, W, 3))
        write_sample(root, "seq00", f"{i:06d}", np.clip(img, 0, 255).astype(np.uint8), ids, labels=UAVID)
    return root


ORACLE = OracleSegmenter(256)  # perfect on clean label-coloured scenes, wrong where perturbations recolour them


def config(weights, **kw):
    base = dict(perturbations=("none", "fog"), monitors=MONITORS, weights=weights,
                core=CoreConfig(n_star=6, working_width=256))
    base.update(kw)
    return CampaignConfig(**base)


def test_campaign_writes_one_shard_per_task_and_a_table(tmp_path, data, weights):
    cfg = config(weights)
    summary = run_campaign(data, tmp_path / "run", cfg, segmenter=ORACLE, execution=Execution(progress=False))
    assert summary["done"] == 6 and summary["faults"] == [] and summary["missing"] == []
    df = results_table(tmp_path / "run", n_boot=200)
    assert len(df) == 2 * len(MONITORS)
    assert (df["images"] == 3).all()
    cands = readouts.load_table(tmp_path / "run", "candidates")
    assert set(cands["monitor"]) == set(MONITORS)
    # gains add up per scenario, hazards in [0, 1]
    np.testing.assert_allclose(df["g_star"], df["g_cm"] + df["g_rm"], atol=1e-12)
    assert cands["true_hazard"].between(0, 1).all() and cands["hazard"].between(0, 1).all()


def test_interrupted_run_resumes_to_the_same_table(tmp_path, data, weights):
    cfg = config(weights)
    full = tmp_path / "full"
    run_campaign(data, full, cfg, segmenter=ORACLE, execution=Execution(progress=False))

    part = tmp_path / "part"
    seen = []

    def stop_after_two(res):
        seen.append(res)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_campaign(data, part, cfg, segmenter=ORACLE, execution=Execution(progress=False, on_result=stop_after_two))
    shards = [p for p in (part / readouts.SHARDS).iterdir() if not p.name.startswith(".")]
    assert len(shards) == 2
    again = run_campaign(data, part, cfg, segmenter=ORACLE, execution=Execution(progress=False))
    assert again["skipped"] == 2 and again["done"] == 4
    a, b = results_table(full, n_boot=200), results_table(part, n_boot=200)
    cols = [c for c in a.columns if c not in TIMING]
    pd.testing.assert_frame_equal(a[cols], b[cols])


def test_bad_image_is_a_recorded_fault(tmp_path, data, weights):
    bad = tmp_path / "bad"
    import shutil

    shutil.copytree(data, bad)
    img = bad / "seq00" / "Images" / "000001.png"
    img.write_bytes(img.read_bytes()[:500])
    summary = run_campaign(bad, tmp_path / "run", config(weights, perturbations=("none",)),
                           segmenter=ORACLE, execution=Execution(progress=False))
    assert len(summary["faults"]) == 1 and "000001" in summary["faults"][0]
    df = results_table(tmp_path / "run", n_boot=100)
    assert (df["images"] == 2).all() and (df["faults"] == 1).all()


def test_other_campaign_in_same_folder_is_refused(tmp_path, data, weights):
    run_campaign(data, tmp_path / "run", config(weights, perturbations=("none",)), segmenter=ORACLE,
                 execution=Execution(progress=False))
    with pytest.raises(readouts.RunError, match="another campaign"):
        run_campaign(data, tmp_path / "run", config(weights, perturbations=("fog",)),
                     segmenter=ORACLE, execution=Execution(progress=False))
    # the same campaign with the weights' card switched to frame + mirror image: other readouts, refused
    flipped = tmp_path / "flipped.pt"
    shutil.copy(weights, flipped)
    card = read_card(weights)
    card["evaluation"] = {"protocol": {"frame_flip": True}}
    write_card(flipped, card)
    run_campaign(data, tmp_path / "run2", config(str(flipped), perturbations=("none",)),
                 segmenter=ORACLE, execution=Execution(progress=False))
    assert json.loads((tmp_path / "run2" / "manifest.json").read_text())["weights"]["frame_flip"] is True
    card["evaluation"] = {"protocol": {"frame_flip": False}}
    write_card(flipped, card)
    with pytest.raises(readouts.RunError, match=r"other weights \(weights.frame_flip: True recorded, False now\)"):
        run_campaign(data, tmp_path / "run2", config(str(flipped), perturbations=("none",)),
                     segmenter=ORACLE, execution=Execution(progress=False))
    card["evaluation"] = {"protocol": {"frame_flip": True, "frame_scales": [1.25]}}
    write_card(flipped, card)
    with pytest.raises(readouts.RunError, match=r"weights.frame_scales: \[1.0\] recorded, \[1.25\] now"):
        run_campaign(data, tmp_path / "run2", config(str(flipped), perturbations=("none",)),
                     segmenter=ORACLE, execution=Execution(progress=False))
    (tmp_path / "run" / "manifest.json").unlink()  # a half-deleted run: shards whose campaign is unknown
    with pytest.raises(readouts.RunError, match="no manifest"):
        run_campaign(data, tmp_path / "run", config(weights, perturbations=("none",)),
                     segmenter=ORACLE, execution=Execution(progress=False))


def test_runs_recorded_before_the_frame_keys_resume(tmp_path):
    """A manifest written before frame_flip / frame_scales existed resumes when nothing changed."""
    base = {"format": readouts.FORMAT_VERSION, "config": {"a": 1}, "data": {"sha256": "d"}}
    area = {"frame_pooling": "area"}
    for was, now in (({"sha256": "w"}, {"frame_flip": False, "frame_scales": [1.0], **area}),  # before the keys
                     ({"sha256": "w", "frame_flip": None},
                      {"frame_flip": None, "frame_scales": None, "frame_pooling": None}),  # no card
                     ({"sha256": "w", "frame_flip": False}, {"frame_flip": False, "frame_scales": [1.0], **area})):
        run = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
        readouts.init_run(run, {**base, "weights": was})
        readouts.init_run(run, {**base, "weights": {"sha256": "w", **now}})  # no RunError
        with pytest.raises(readouts.RunError, match="frame_scales"):
            readouts.init_run(run, {**base, "weights": {"sha256": "w", **now, "frame_scales": [1.25]}})
        if now["frame_pooling"]:
            with pytest.raises(readouts.RunError, match="frame_pooling"):
                readouts.init_run(run, {**base, "weights": {"sha256": "w", **now, "frame_pooling": "conservative"}})


def test_shared_grid_equals_single_configuration_runs(tmp_path, data, weights):
    """Work sharing changes nothing but timings: verdicts equal the monitored pipeline's, config by config."""
    cfg = config(weights, perturbations=("none",))
    seg = ORACLE
    run_campaign(data, tmp_path / "run", cfg, segmenter=seg, execution=Execution(progress=False))
    cands = readouts.load_table(tmp_path / "run", "candidates")
    sample = plan(data, cfg)[0].sample
    rgb = read_image(sample.image_path)
    for mon in MONITORS:
        el = EmergencyLanding(PipelineConfig(core=cfg.core, monitor=mon, time_budget_s=None, evaluate_all=True),
                              segmenter=seg)
        d = el.decide(rgb)
        mine = cands[(cands["key"] == sample.key) & (cands["monitor"] == mon)].sort_values("rank")
        assert len(mine) == len(d.candidates) > 0
        assert mine["accepted"].tolist() == [c.monitor.accepted for c in d.candidates], mon
        assert mine["x"].tolist() == [c.x for c in d.candidates]


def test_cli_campaign_and_table(tmp_path, data, weights, capsys):
    run = tmp_path / "run"
    code = main(["campaign", "--data", str(data), "--out", str(run), "--perturbations", "none", "pixel_trap",
                 "--monitors", "lhd", "--weights", weights, "--images", "2", "--quiet"])
    assert code == 0
    assert main(["table", str(run), "--compare", "--boot", "100"]) == 0
    out = capsys.readouterr().out
    assert "pixel_trap" in out and "ours / paper" in out
    assert "Does the core model beat the default action" in out and "Where the time went" in out
    assert "What no monitor can prevent" in out and "| none (s3) | 2 |" in out
    assert (run / "results.csv").is_file() and (run / "results.md").is_file()
    stages = stage_table(run)
    assert stages["tasks"].eq(4).all()  # 2 perturbations x 2 images, one row per task not per monitor
    parts = stages[stages["stage"] != "task total"]
    assert parts["seconds"].sum() == pytest.approx(stages["seconds"].iloc[-1], rel=1e-9)
    assert (stages.loc[stages["stage"] == "segment frame", "seconds"] > 0).all()
    assert wall_seconds(run) > 0
    assert main(["campaign", "--data", str(data), "--out", str(tmp_path / "r2"), "--perturbations", "smoke"]) == 2
    assert "unknown perturbation" in capsys.readouterr().err


def test_dask_local_cluster_gives_the_same_readouts(tmp_path, data, weights):
    """The same tasks on a real dask.distributed LocalCluster: same readouts as the in-process run."""
    pytest.importorskip("dask.distributed")
    cfg = config(weights, perturbations=("none",), monitors=("lhd",), core=CoreConfig(n_star=6))
    run_campaign(data, tmp_path / "local", cfg, execution=Execution(progress=False))
    summary = run_campaign(data, tmp_path / "dask", cfg, execution=Execution(progress=False, jobs=2, backend="dask"))
    assert summary["done"] == 3 and not summary["faults"]
    a = readouts.load_table(tmp_path / "local", "images").sort_values("key").reset_index(drop=True)
    b = readouts.load_table(tmp_path / "dask", "images").sort_values("key").reset_index(drop=True)
    keep = [c for c in a.columns if not c.endswith("_s")]
    pd.testing.assert_frame_equal(a[keep], b[keep])


def test_a_task_that_left_no_shard_is_reported_and_rerun(tmp_path, data, weights, monkeypatch):
    """A worker that dies after its task (no shard written) is named in the summary; re-running completes it."""
    from assurance.campaign import run as C

    write = readouts.write_shard
    lost = []

    def lose_one(run_dir, name, rows):
        if not lost:
            lost.append(name)
            return
        write(run_dir, name, rows)

    monkeypatch.setattr(readouts, "write_shard", lose_one)
    cfg = config(weights, perturbations=("none",))
    summary = run_campaign(data, tmp_path / "run", cfg, segmenter=ORACLE, execution=Execution(progress=False))
    assert summary["missing"] == lost and "left no shard" in C.describe(summary)
    monkeypatch.setattr(readouts, "write_shard", write)
    again = run_campaign(data, tmp_path / "run", cfg, segmenter=ORACLE, execution=Execution(progress=False))
    assert again["done"] == 1 and again["skipped"] == 2 and again["missing"] == []


def test_candidate_audit_of_a_perfect_segmenter_finds_no_unsafe_candidate(data):
    from assurance.fitting.candidate_audit import candidate_audit

    core = CoreConfig(n_star=6, working_width=256)
    audit = candidate_audit(ORACLE, data, core=core)
    assert audit["images"] == 3 and audit["candidates"] > 0
    assert audit["unsafe"] == 0 and audit["unsafe_share"] == 0.0 and audit["top_unsafe_share"] == 0.0


class _BlindSegmenter:
    """Sees open grass everywhere: every candidate it offers is judged on the ground truth alone."""

    def predict_frame(self, rgb):
        h = round(rgb.shape[0] * 256 / rgb.shape[1])
        probs = np.full((8, h, 256), 0.01, np.float32)
        probs[5] = 0.93
        return probs


def test_candidate_audit_says_what_makes_the_unsafe_candidates_unsafe(data):
    from assurance.fitting.candidate_audit import _unsafe_cause, candidate_audit

    assert _unsafe_cause(np.array([5, 5, 0, 4], np.uint8), UAVID) is None
    assert _unsafe_cause(np.array([5, 2, 2, 1], np.uint8), UAVID) == ("road", 0.75)
    audit = candidate_audit(_BlindSegmenter(), data, core=CoreConfig(n_star=6, working_width=256))
    assert audit["unsafe"] > 0
    assert sum(audit["unsafe_by_class"].values()) == audit["unsafe"]
    assert set(audit["unsafe_by_class"]) <= {"building", "road", "static_car", "moving_car", "outside the image"}
    assert 0 < audit["median_forbidden_share"] <= 1
