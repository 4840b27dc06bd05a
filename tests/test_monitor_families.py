"""The benchmark's detector families: hand-computed scores on tiny arrays, registration, refusals, and
the fitted records (plain JSON, hashed, bound to their network)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from test_learned_monitor import CORE, WW, RoadBlindFrame, splits  # noqa: F401  (the module-scoped fixture)

from el.classes.labels import UAVID
from el.monitors import build_monitor, monitor_names
from el.monitors.capabilities import MonitorSupportError

FAMILIES = ("odin", "doctor", "mahalanobis", "gmm", "outside_box")


def _disc(p: list[list[float]]) -> np.ndarray:
    """Softmax (8, m) of m pixels from two-class rows (classes 4 and 5, both safe in UAVid)."""
    out = np.zeros((8, len(p)), np.float64)
    for j, (a, b) in enumerate(p):
        out[4, j], out[5, j] = a, b
    return out


def test_the_families_are_registered_and_build_by_name():
    names = monitor_names()
    assert all(f in names for f in FAMILIES)
    assert build_monitor("odin:temperature=2.0", labels=UAVID).name == "odin:temperature=2.0"
    assert build_monitor("doctor:variant=beta", labels=UAVID).name == "doctor:variant=beta"
    with pytest.raises(ValueError, match="model"):
        build_monitor("mahalanobis", labels=UAVID)  # a fitted family needs its record


def test_odin_is_the_temperature_scaled_softmax_of_the_logits():
    m = build_monitor("odin:temperature=2.0", labels=UAVID, network_classes=2)
    # p = (0.8, 0.2): p^(1/2) = (0.8944, 0.4472), top 0.8944 / 1.3416 = 2/3; u = (1 - 2/3) / (1 - 1/2) = 2/3
    assert m.uncertainty(_disc([[0.8, 0.2]]))[0] == pytest.approx(2.0 / 3.0)
    logits = np.log(np.array([0.8, 0.2])) + 7.0  # any logits with this softmax
    z = np.exp(logits / 2.0)
    assert m.uncertainty(_disc([[0.8, 0.2]]))[0] == pytest.approx((1 - z.max() / z.sum()) / 0.5)
    j = m.judge(m.reduce(_disc([[0.8, 0.2], [0.99, 0.01]])[:, :, None], np.ones((2, 1), bool)))
    assert j.score == pytest.approx(2.0 / 3.0) and j.accepted  # the worst pixel; below 1: no forbidden pixel


def test_odin_input_perturbation_is_refused_in_one_line():
    with pytest.raises(MonitorSupportError) as err:
        build_monitor("odin:eps=0.002", labels=UAVID)
    assert "\n" not in str(err.value) and "gradient" in str(err.value)


def test_doctor_alpha_and_beta_by_hand():
    a = build_monitor("doctor", labels=UAVID, network_classes=2)
    b = build_monitor("doctor:variant=beta", labels=UAVID, network_classes=2)
    # g = 0.8^2 + 0.2^2 = 0.68: (1 - g) / g = 0.470588 over C - 1 = 1;  beta: 0.2 / 0.8 = 0.25
    assert a.uncertainty(_disc([[0.8, 0.2]]))[0] == pytest.approx(0.32 / 0.68)
    assert b.uncertainty(_disc([[0.8, 0.2]]))[0] == pytest.approx(0.25)
    with pytest.raises(ValueError, match="variant"):
        build_monitor("doctor:variant=gamma", labels=UAVID)


def test_a_forbidden_pixel_scores_above_one_as_for_msp():
    p = np.zeros((8, 2))
    p[2, 0], p[5, 1] = 1.0, 1.0  # road on one of two pixels
    for spec in ("odin", "doctor"):
        j = build_monitor(spec, labels=UAVID).judge(p)
        assert j.score == pytest.approx(1.5) and not j.accepted


def test_feature_space_scores_by_hand():
    from el.monitors.gmm import gmm_score
    from el.monitors.mahalanobis import mahalanobis_score
    from el.monitors.outside_box import box_score

    assert mahalanobis_score(np.array([[1.0, 2.0]]), np.zeros(2), np.diag([1.0, 0.25]))[0] == pytest.approx(2.0)
    one = gmm_score(np.array([[1.0]]), np.ones(1), np.zeros((1, 1)), np.ones((1, 1, 1)))[0]
    assert one == pytest.approx(0.5 + 0.5 * math.log(2 * math.pi))  # -log N(1; 0, 1)
    two = gmm_score(np.array([[0.0]]), np.array([0.5, 0.5]), np.array([[0.0], [10.0]]), np.ones((2, 1, 1)))[0]
    assert two == pytest.approx(math.log(2.0) + 0.5 * math.log(2 * math.pi), abs=1e-9)  # half the mass far away
    lo, hi = np.array([[0.0, 0.0], [5.0, 5.0]]), np.array([[1.0, 2.0], [6.0, 6.0]])
    assert box_score(np.array([[0.5, 1.0], [1.5, 1.0], [-1.0, 1.0]]), lo, hi).tolist() == [0.0, 0.5, 1.0]


@pytest.fixture(scope="module")
def records(splits, tmp_path_factory):  # noqa: F811
    from assurance.fitting.detectors import FAMILIES as FITTED
    from assurance.fitting.detectors import detector_document, fit_detector_body
    from assurance.fitting.learned_monitor import FeatureSettings, collect_candidates

    train, val = splits
    seg = RoadBlindFrame(WW)
    on_core = FeatureSettings(core=CORE)
    tr, he = collect_candidates(train, seg, features=on_core), collect_candidates(val, seg, features=on_core)
    out = tmp_path_factory.mktemp("detectors")
    paths = {}
    for family in FITTED:
        body = fit_detector_body(family, tr, he, labels=UAVID, weights={"sha256": seg.weights_sha256},
                                 components=2)
        paths[family] = out / f"{family}.json"
        paths[family].write_text(json.dumps(detector_document(body)))
    return paths


def test_fitted_records_are_plain_hashed_json_with_their_criterion(records):
    for family, path in records.items():
        doc = json.loads(path.read_text())
        assert doc["format"] == "uav-el-candidate-detector/1" and len(doc["sha256"]) == 64
        b = doc["body"]
        assert b["family"] == family and b["criterion"]["name"] == "tnr-at-recall"
        m = build_monitor(f"{family}:model={path}", labels=UAVID)
        assert m.threshold == b["threshold"] and m.model_sha256 == doc["sha256"]
        m.check_network(RoadBlindFrame(WW))  # bound to the network it was fitted on


def test_altered_foreign_or_wrong_family_records_are_refused(records, tmp_path):
    from el.monitors.fitted import DetectorModelError

    doc = json.loads(records["gmm"].read_text())
    doc["body"]["threshold"] = 0.0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(DetectorModelError, match="altered"):
        build_monitor(f"gmm:model={bad}", labels=UAVID)
    with pytest.raises(DetectorModelError, match="not 'gmm'"):
        build_monitor(f"gmm:model={records['mahalanobis']}", labels=UAVID)
    m = build_monitor(f"outside_box:model={records['outside_box']}", labels=UAVID)

    class Other(RoadBlindFrame):
        weights_sha256 = "ab" * 32

    with pytest.raises(DetectorModelError, match="refit"):
        m.check_network(Other(WW))


def test_a_campaign_scores_every_family_and_the_benchmark_ranks_them(records, splits, tmp_path, capsys):  # noqa: F811
    from assurance import cli
    from assurance.campaign import readouts
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign

    _, val = splits
    specs = ("lhd", "msp", "odin", "doctor", *(f"{f}:model={p}" for f, p in records.items()))
    config = CampaignConfig(perturbations=("none", "brightness"), monitors=specs, core=CORE)
    summary = run_campaign(val, tmp_path / "run", config, segmenter=RoadBlindFrame(WW),
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    cands = readouts.load_table(tmp_path / "run", "candidates")
    assert set(cands["monitor"]) >= set(specs) and np.isfinite(cands["score"]).all()
    code = cli.main(["benchmark", str(tmp_path / "run"), "--out", str(tmp_path / "bench"), "--blocks", "scene"])
    md = capsys.readouterr().out
    assert code == 0, md
    assert "Friedman" in md and "mean rank" in md and "mahalanobis:model=mahalanobis.json" in md
    assert (tmp_path / "bench" / "cd.png").stat().st_size > 1000
    import pandas as pd

    table = pd.read_csv(tmp_path / "bench" / "benchmark.csv")
    assert len(table) == len(specs) * 5 * 2  # monitors x default criteria x perturbations
    assert set(table["criterion"]) == {"fewest-unsafe", "g-star", "f1", "g-mean", "tnr-at-recall"}
    code = cli.main(["sweep", str(tmp_path / "run"), "--criterion", "g-mean", "--out", str(tmp_path / "sw"),
                     "--monitors", "msp", "odin"])
    assert code == 0
    assert "criterion `g-mean`" in (tmp_path / "sw" / "sweep.md").read_text()


def test_the_flight_pipeline_runs_a_fitted_detector_by_name(records, splits):  # noqa: F811
    from el.flight.pipeline import EmergencyLanding, PipelineConfig

    _, val = splits
    image = next(val.glob("**/Images/*.png"))
    for family in ("gmm", "outside_box"):
        spec = f"{family}:model={records[family]}"
        d = EmergencyLanding(PipelineConfig(core=CORE, monitor=spec, evaluate_all=True, time_budget_s=None),
                             segmenter=RoadBlindFrame(WW)).decide(image)
        assert not d.reason.startswith("fault"), d.reason
        assert d.candidates and all(c.monitor.name == spec for c in d.candidates)
        assert all(c.monitor.accepted == (c.monitor.score <= c.monitor.threshold) for c in d.candidates)
