"""Scores in the readouts: AUROC per configuration in ``uav-el table``, ROC curves in the report, old runs."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pandas as pd
import pytest
from helpers import OracleSegmenter, scene_ids

from assurance.analysis.scores import auroc, auroc_table, roc_curve
from assurance.campaign import readouts
from assurance.campaign.run import CampaignConfig, Execution, run_campaign
from assurance.dataio.uavid import write_sample
from el.classes.labels import UAVID, ids_to_colors
from el.geometry.config import CoreConfig

MONITORS = ("lhd", "lhd+ch:tau=0.25", "lhd+mcd:n=10,rho=0.9", "msp", "entropy:threshold=0.5")


def test_auroc_is_the_pairwise_probability_with_ties_as_half():
    rng = np.random.default_rng(0)
    for _ in range(20):
        s = rng.integers(0, 5, 30).astype(float)
        y = rng.random(30) < 0.4
        pairs = [(a, b) for a, b in itertools.product(s[y], s[~y])]
        want = np.mean([1.0 if a > b else 0.5 if a == b else 0.0 for a, b in pairs])
        assert auroc(s, y) == pytest.approx(want)
    assert np.isnan(auroc([0.1, 0.2], [True, True]))
    fpr, tpr, t = roc_curve([0.1, 0.4, 0.35, 0.8], [False, False, True, True])
    assert (fpr[0], tpr[0], fpr[-1], tpr[-1]) == (0, 0, 1, 1) and np.all(np.diff(tpr) >= 0)
    assert np.trapezoid(tpr, fpr) == pytest.approx(0.75)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("scores")
    rng = np.random.default_rng(0)
    for i in range(3):
        ids = scene_ids(256, 144, seed=i, road_col=40 + 60 * i)
        img = np.clip(ids_to_colors(ids).astype(int) + rng.integers(-30, 30, (144, 256, 3)), 0, 255)
        write_sample(root / "data", "seq00", f"{i:06d}", img.astype(np.uint8), ids, labels=UAVID)
    config = CampaignConfig(perturbations=("none", "fog"), monitors=MONITORS,
                            core=CoreConfig(n_star=8, working_width=128))
    summary = run_campaign(root / "data", root / "run", config, segmenter=OracleSegmenter(128),
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    return root / "run"


def test_readouts_hold_scores_and_table_prints_auroc_and_costs(run, capsys):
    from assurance.cli import main

    cands = readouts.load_table(run, "candidates")
    assert {"score", "threshold"} <= set(cands.columns) and cands["score"].notna().all()
    assert (cands["accepted"] == ~(cands["score"] > cands["threshold"])).all()
    tab = auroc_table(cands, n_boot=200)
    assert len(tab) == 2 * len(MONITORS) and set(tab["monitor"]) == set(MONITORS)
    fog = tab[tab["perturbation"] == "fog"]
    assert fog["unsafe"].gt(0).all() and fog["auroc"].between(0, 1).all()
    assert main(["table", str(run), "--boot", "200"]) == 0
    out = capsys.readouterr().out
    assert "### Monitor scores: AUROC" in out and "`msp`" in out
    assert "Monitoring time per candidate" in out and "| `lhd` |" in out


def test_runs_without_scores_still_load(run, tmp_path, capsys):
    import shutil

    from assurance.cli import main
    from assurance.evidence.plots import roc_figure

    old = tmp_path / "old"
    shutil.copytree(run, old)
    for shard in (old / "shards").iterdir():
        p = shard / "candidates.parquet"
        pd.read_parquet(p).drop(columns=["score", "threshold"]).to_parquet(p, index=False)
        (shard / "SHA256SUMS").unlink(missing_ok=True)  # a run from before scores predates shard hashes too
    (old / "shards.json").unlink(missing_ok=True)
    manifest = json.loads((old / "manifest.json").read_text())
    manifest.pop("integrity", None)
    (old / "manifest.json").write_text(json.dumps(manifest))
    cands = readouts.load_table(old, "candidates")
    assert auroc_table(cands)["auroc"].isna().all()
    assert roc_figure(cands, list(MONITORS), "lhd") is None
    assert roc_figure(readouts.load_table(run, "candidates"), list(MONITORS), "lhd").startswith("data:image/png")
    assert main(["table", str(old), "--boot", "50"]) == 0
    out = capsys.readouterr().out
    assert "| none (s3) | `lhd` |" in out and "| - |" in out
