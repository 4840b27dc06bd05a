"""Shared fixtures of the test suite (the run binding, ``campaign_run`` and ``requirement_registry`` are the
plugin's: ``assurance.requirements.pytest_plugin``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests/helpers.py for tests in sub-folders

# Imported once here: the run verification in pytest_configure needs them, and pytester's in-process
# sessions would otherwise import pandas inside a session and drop it afterwards (two copies of its types).
import assurance.campaign.integrity  # noqa: E402, F401
from assurance.campaign.run import Execution  # noqa: E402
from el.classes.labels import UAVID

_THREAD_COUNTS: list[tuple[int, int]] = []  # torch's and OpenCV's thread counts when the session started


def pytest_configure(config: pytest.Config) -> None:
    import cv2
    import torch

    _THREAD_COUNTS[:] = [(torch.get_num_threads(), cv2.getNumThreads())]  # before any fixture changes them


# ------------------------------------------------------------------------------------------------
# Tiny campaign runs for the tests of the requirement plugin and the evidence report
# ------------------------------------------------------------------------------------------------
TINY_W, TINY_H, TINY_WW = 256, 144, 128
TINY_IMAGES = 10  # the registry's minimum per perturbation (EL-R08)


def tiny_scene(i: int):
    """Label map: clutter on the left, low vegetation on the right, a road under the default area (so the
    default action is hazardous and the system's gain measurable), a building block and a few trees."""
    import numpy as np

    rng = np.random.default_rng(i)
    ids = np.zeros((TINY_H, TINY_W), np.uint8)
    ids[:, TINY_W // 2:] = 5
    c = TINY_W // 2 + int(rng.integers(-6, 7))
    ids[:, c - 4:c + 4] = 2
    ids[: TINY_H // 3, 10:60] = 1
    for _ in range(3):
        y, x = int(rng.integers(TINY_H // 3, TINY_H - 6)), int(rng.integers(0, TINY_W - 6))
        ids[y:y + 5, x:x + 5] = 4
    return ids


class GrassIsRoadOracle:
    """A perfect frame segmenter whose HD patches see low vegetation as road: the monitor rejects every
    candidate on grass (deterministic rejections, for tests of the monitor-coverage check)."""

    def __init__(self, working_width: int) -> None:
        from helpers import OracleSegmenter

        self._oracle = OracleSegmenter(working_width)

    def predict_frame(self, rgb):
        return self._oracle.predict_frame(rgb)

    def predict_patch(self, rgb):
        import numpy as np
        from helpers import nearest_class

        ids = nearest_class(rgb)
        ids[ids == 5] = 2
        probs = np.zeros((8, *ids.shape), np.float32)
        np.put_along_axis(probs, ids[None].astype(np.intp), 1.0, axis=0)
        return probs

    def mc_dropout(self, rgb, n, keep_prob, seed):
        import numpy as np

        return np.repeat(self.predict_patch(rgb)[None], n, axis=0)


@pytest.fixture(scope="session")
def tiny_campaign(tmp_path_factory):
    """A finished campaign on tiny label-coloured scenes: the six perturbations x 10 images x 2 monitors,
    perfect segmentation (tests/helpers.OracleSegmenter). Returns a dict: data, weights, run."""
    import torch
    from helpers import OracleSegmenter

    from assurance.campaign.run import CampaignConfig, Execution, run_campaign
    from assurance.dataio.uavid import write_sample
    from assurance.fitting.network.weights_io import save_weights
    from assurance.perturbations import PAPER_PERTURBATIONS
    from el.classes.labels import ids_to_colors
    from el.geometry.config import CoreConfig
    from el.segmentation.architectures import build_model
    from el.segmentation.model import ArchConfig

    root = tmp_path_factory.mktemp("tiny_campaign")
    for i in range(TINY_IMAGES):
        ids = tiny_scene(i)
        write_sample(root / "data", "seq00", f"{i:06d}", ids_to_colors(ids), ids, labels=UAVID)
    torch.manual_seed(0)
    weights = root / "tiny.pt"
    save_weights(build_model(ArchConfig(widths=(8, 8, 8), decoder_channels=8)), weights)
    config = CampaignConfig(perturbations=PAPER_PERTURBATIONS, monitors=("lhd", "lhd+ch:tau=0.25"),
                            core=CoreConfig(n_star=6, working_width=TINY_WW), weights=str(weights))
    summary = run_campaign(root / "data", root / "run", config, segmenter=OracleSegmenter(TINY_WW),
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    return {"data": root / "data", "weights": weights, "run": root / "run", "config": config}


@pytest.fixture(scope="session")
def tiny_run_without(tiny_campaign, tmp_path_factory):
    """``tiny_run_without(name)``: a copy of the tiny campaign run without one perturbation (its shards
    removed and the manifest's configuration updated), as if the campaign had never evaluated it."""
    import json
    import shutil

    made = {}

    def make(perturbation: str):
        if perturbation in made:
            return made[perturbation]
        run = tmp_path_factory.mktemp(f"without_{perturbation}") / "run"
        shutil.copytree(tiny_campaign["run"], run)
        from assurance.campaign.readouts import record_shards

        for shard in (run / "shards").iterdir():
            if shard.name.startswith(f"{perturbation}-s"):
                shutil.rmtree(shard)
                record_shards(run, {shard.name: None})  # never evaluated, not deleted: out of the index too
        man = json.loads((run / "manifest.json").read_text())
        man["config"]["perturbations"] = [p for p in man["config"]["perturbations"] if p != perturbation]
        (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True))
        from assurance.attest.keys import load_signing_key
        from assurance.campaign.attestation import sign_run

        sign_run(run, load_signing_key())  # as the campaign would have signed it
        made[perturbation] = run
        return run

    return make


@pytest.fixture(scope="session")
def monitor_runs(tiny_campaign, tmp_path_factory):
    """Two small runs whose monitor rejects every candidate on grass: 'good' (the real decision loop)
    and 'broken' (a pipeline variant that ignores the monitor and lands on rank 0 regardless)."""
    import el.flight.kernel as kernel
    from assurance.campaign import task as campaign
    from assurance.campaign.run import CampaignConfig, run_campaign

    root = tmp_path_factory.mktemp("monitor_runs")
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), images=3,
                            core=tiny_campaign["config"].core, weights=tiny_campaign["config"].weights)
    seg = GrassIsRoadOracle(TINY_WW)
    run_campaign(tiny_campaign["data"], root / "good", config, segmenter=seg, execution=Execution(progress=False))
    from el.monitors.walk import WalkOutcome

    real_walk = campaign.walk_candidates

    def lands_on_top(n, judge, *args, **kwargs):  # lands on the top candidate, accepted or not
        out = real_walk(n, judge, *args, **kwargs)
        return WalkOutcome(0 if n else None, "accepted" if n else "no_candidate", out.verdicts, out.examined,
                           out.overhead_s)

    campaign.walk_candidates = kernel.walk_candidates = lands_on_top  # the task's readouts and its decisions
    try:
        run_campaign(tiny_campaign["data"], root / "broken", config, segmenter=seg, execution=Execution(progress=False))
    finally:
        campaign.walk_candidates = kernel.walk_candidates = real_walk
    return {"good": root / "good", "broken": root / "broken"}


@pytest.fixture(scope="module")
def one_torch_thread():
    """Tiny tensors: one torch thread is faster, and immune to a busy shared CPU."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(autouse=True)
def _restore_thread_counts():
    """Code under test sets process-wide thread counts (``Segmenter.load(threads=...)``, ``uav-el synth`` sets
    OpenCV's to 1), also in module fixtures: put back the session's first counts after each test, so no test sees
    another's (float sums, and OpenCV's distance transform, depend on them)."""
    import cv2
    import torch

    yield
    torch_threads, cv2_threads = _THREAD_COUNTS[0]
    if torch.get_num_threads() != torch_threads:
        torch.set_num_threads(torch_threads)
    if cv2.getNumThreads() != cv2_threads:
        cv2.setNumThreads(cv2_threads)


@pytest.fixture(scope="session", autouse=True)
def _private_key_home(tmp_path_factory):
    """Signing keys: the suite never reads or writes the user's key file (``assurance.attest.keys``); each
    session has a fresh key home, put back when it ends (``uav-el verify`` signs after its in-process session)."""
    saved = {k: os.environ.get(k) for k in ("XDG_CONFIG_HOME", "UAV_EL_SIGNING_KEY", "UAV_EL_TRUSTED_KEYS")}
    os.environ["XDG_CONFIG_HOME"] = str(tmp_path_factory.mktemp("key_home"))
    os.environ.pop("UAV_EL_SIGNING_KEY", None)
    os.environ.pop("UAV_EL_TRUSTED_KEYS", None)
    yield
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
