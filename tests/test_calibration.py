"""Calibration with a guarantee: the bound holds at the stated rate; cards are checked; land, the pipeline,
campaigns and the EL-R16 check use them."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import OracleSegmenter, nearest_class, scene_ids
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from assurance.dataio.uavid import write_sample
from assurance.fitting.calibration import CalibrationError, calibrate_threshold, min_unsafe_needed
from el.classes.labels import CLASS_IDS, UAVID, ids_to_colors

DISTS = {
    "normal": (lambda rng, size: rng.normal(0.3, 0.2, size), lambda t: stats.norm.cdf(t, 0.3, 0.2)),
    "exponential": (lambda rng, size: rng.exponential(0.1, size), lambda t: stats.expon.cdf(t, scale=0.1)),
    # LHD-like: many ties (a fraction of k of 20 pixels); accepted iff score <= t, P(S <= t) exactly
    "atoms": (lambda rng, size: rng.binomial(20, 0.3, size) / 20,
              lambda t: stats.binom.pmf(np.arange(21), 20, 0.3)[np.arange(21) / 20 <= np.asarray(t)[..., None]].sum()
              if np.ndim(t) == 0 else np.array([stats.binom.pmf(np.arange(21), 20, 0.3)[np.arange(21) / 20 <= x].sum()
                                                for x in t])),
}


@settings(max_examples=30, deadline=None, derandomize=True)
@given(dist=st.sampled_from(sorted(DISTS)), n=st.integers(60, 400), miss=st.sampled_from([0.05, 0.1, 0.2]),
       conf=st.sampled_from([0.8, 0.9, 0.95]), seed=st.integers(0, 2**31))
def test_bound_holds_at_the_stated_rate_over_seeded_draws(dist, n, miss, conf, seed):
    """Over 1000 calibration samples, P(accept unsafe) > miss happens at most as often as 1 - conf allows."""
    draw, cdf = DISTS[dist]
    rng = np.random.default_rng(seed)
    reps = 1000
    if n < min_unsafe_needed(miss, conf):
        with pytest.raises(CalibrationError, match="are needed"):
            calibrate_threshold(draw(rng, n), miss, conf)
        return
    samples = draw(rng, (reps, n))
    first = [calibrate_threshold(x, miss, conf) for x in samples[:3]]
    k = first[0]["k"]
    assert all(r["k"] == k and r["bound"] <= miss + 1e-12 and r["accepted"] <= k - 1 for r in first)
    thresholds = np.nextafter(np.sort(samples, axis=1)[:, k - 1], -np.inf)  # what calibrate_threshold picks
    assert [r["threshold"] for r in first] == thresholds[:3].tolist()
    violations = int((cdf(thresholds) > miss).sum())  # the true miss rate at each chosen threshold
    limit = stats.binom.ppf(1 - 1e-6, reps, 1 - conf)  # what 1 - conf allows, with a 1e-6 false alarm
    assert violations <= limit


def test_threshold_is_just_below_the_kth_score_and_too_few_is_an_error():
    s = np.arange(100) / 100.0
    res = calibrate_threshold(s, 0.05, 0.95)
    k = res["k"]
    assert stats.binom.cdf(k - 1, 100, 0.05) <= 0.05 < stats.binom.cdf(k, 100, 0.05)
    assert s[k - 2] <= res["threshold"] < s[k - 1] and res["accepted"] == k - 1
    assert min_unsafe_needed(0.05, 0.95) == 59
    with pytest.raises(CalibrationError, match="at least 59"):
        calibrate_threshold(s[:58], 0.05, 0.95)
    with pytest.raises(CalibrationError, match="miss rate"):
        calibrate_threshold(s, 1.5, 0.95)


class RoadBlindFrame(OracleSegmenter):
    """Frames: road seen as low vegetation (candidates land on roads); patches: perfect (LHD sees the road)."""

    def predict_frame(self, rgb):
        ids = nearest_class(rgb)
        ids[ids == CLASS_IDS["road"]] = CLASS_IDS["low_vegetation"]
        return super().predict_frame(ids_to_colors(ids))


@pytest.fixture(scope="module")
def val(tmp_path_factory):
    root = tmp_path_factory.mktemp("val")
    for i in range(4):
        ids = scene_ids(256, 144, seed=i, road_col=30 + 50 * i)
        ids[:, 150 + 10 * i: 175 + 10 * i] = CLASS_IDS["road"]  # a wide road: candidates on it
        write_sample(root, "seq00", f"{i:06d}", ids_to_colors(ids), ids, labels=UAVID)
    return root


@pytest.fixture(scope="module")
def card(val, tmp_path_factory, ):
    import el.segmentation as seg_module
    from assurance.cli import main

    out = tmp_path_factory.mktemp("card") / "calib.json"
    real = seg_module.Segmenter.load
    seg_module.Segmenter.load = classmethod(lambda cls, *a, **k: RoadBlindFrame(1024))
    try:
        code = main(["calibrate", "--data", str(val), "--monitor", "lhd", "--miss-rate", "0.2", "--confidence",
                     "0.8", "--out", str(out)])
    finally:
        seg_module.Segmenter.load = real
    assert code == 0
    return out


def test_calibrate_writes_a_card_that_records_what_it_rests_on(card, capsys):
    doc = json.loads(card.read_text())
    b = doc["body"]
    assert b["monitor"] == "lhd" and b["spec"] == f"lhd:threshold={b['threshold']!r}"
    c = b["counts"]
    assert c["unsafe"] >= min_unsafe_needed(0.2, 0.8) and c["unsafe"] + c["safe"] == c["candidates"]
    assert b["bound"] <= 0.2 and c["unsafe_accepted"] / c["unsafe"] <= 0.2
    assert len(b["split"]["sha256"]) == 64 and b["split"]["images"] == 4
    assert {"miss_rate", "confidence", "order_statistic_k", "guarantee", "weights"} <= set(b)


def test_pipeline_and_land_use_the_card_and_refuse_an_altered_one(card, val, tmp_path, capsys):
    from assurance import cli
    from el.flight.pipeline import EmergencyLanding, PipelineConfig

    doc = json.loads(card.read_text())
    t = doc["body"]["threshold"]
    image = next(val.glob("**/Images/*.png"))
    seg = RoadBlindFrame(1024)
    d = EmergencyLanding(PipelineConfig(monitor="lhd", calibration=str(card), evaluate_all=True,
                                        time_budget_s=None), segmenter=seg).decide(image)
    assert not d.reason.startswith("fault"), d.reason
    assert all(c.monitor.threshold == t and c.monitor.name == doc["body"]["spec"] for c in d.candidates)
    d = EmergencyLanding(PipelineConfig(monitor="msp", calibration=str(card)), segmenter=seg).decide(image)
    assert d.action == "default" and "calibrates 'lhd', not 'msp'" in d.reason

    bad = tmp_path / "bad.json"
    doc["body"]["threshold"] = 0.9
    bad.write_text(json.dumps(doc))
    d = EmergencyLanding(PipelineConfig(monitor="lhd", calibration=str(bad)), segmenter=seg).decide(image)
    assert d.action == "default" and "calibration card altered" in d.reason
    assert cli.main(["land", str(image), "--calibration", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.json" in err[0] and "altered" in err[0]


def test_campaign_with_the_card_and_the_el_r16_check(card, val, tmp_path):
    from assurance.campaign import readouts
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign
    from assurance.requirements.calibration_check import check_calibrated_miss_rate
    from el.geometry.config import CoreConfig
    from el.monitors.calibration import load_calibration

    c = load_calibration(card)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd", c.spec), core=CoreConfig())
    run_campaign(val, tmp_path / "run", config, segmenter=RoadBlindFrame(1024), execution=Execution(progress=False))
    cands = readouts.load_table(tmp_path / "run", "candidates")
    ev = check_calibrated_miss_rate(cands, c)
    assert ev.status == "pass" and "with its own verdicts" in ev.summary  # same scenes: at most k - 1 accepted
    ev2 = check_calibrated_miss_rate(cands[cands["monitor"] == "lhd"], c)
    assert ev2.status == "pass" and ev2.rows[0]["accepted"] == ev.rows[0]["accepted"]
    strict = load_calibration(card)
    strict.body["miss_rate"] = 0.0
    assert check_calibrated_miss_rate(cands, strict).status == ("fail" if ev.rows[0]["accepted"] else "pass")
    assert check_calibrated_miss_rate(cands.drop(columns=["score"]).iloc[:0], c).status == "insufficient"


@pytest.mark.parametrize("given, expected", [([], 0.9), (["--confidence", "0.99"], 0.99)])
def test_calibrate_takes_the_confidence_of_the_system_files_targets(tmp_path, monkeypatch, given, expected):
    """A system file's [targets] confidence is the card's unless --confidence says otherwise (it was 0.95 always)."""
    from assurance import cli
    from assurance.fitting import calibration

    seen = {}

    def capture(data, monitor, *, rule, **kwargs):
        seen["confidence"] = rule.confidence
        raise ValueError("stop here")

    monkeypatch.setattr(calibration, "calibrate_on_data", capture)
    (tmp_path / "val").mkdir()
    system = tmp_path / "uav-el.toml"
    system.write_text('format = "uav-el-system/1"\n[targets]\nconfidence = 0.9\n')
    assert cli.main(["calibrate", "--system", str(system), "--data", str(tmp_path / "val"), "--monitor", "msp",
                     "--out", str(tmp_path / "card.json"), *given]) == 2
    assert seen["confidence"] == expected
