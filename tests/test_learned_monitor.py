"""The learned candidate monitor: features, training and selection, the hash-checked JSON model (tampered
file refused), and its use by name in the pipeline, uav-el land, campaigns and calibration."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import OracleSegmenter, nearest_class, scene_ids

from assurance.campaign.run import Execution
from assurance.dataio.uavid import write_sample
from el.classes.labels import CLASS_IDS, UAVID, ids_to_colors
from el.geometry.config import CoreConfig

WW = 256
CORE = CoreConfig(working_width=WW)


class RoadBlindFrame(OracleSegmenter):
    """Frames: road seen as low vegetation (candidates land on roads); patches: perfect."""

    def predict_frame(self, rgb):
        ids = nearest_class(rgb)
        ids[ids == CLASS_IDS["road"]] = CLASS_IDS["low_vegetation"]
        return super().predict_frame(ids_to_colors(ids))


def _split(root, n, offset):
    for i in range(n):
        ids = scene_ids(256, 144, seed=offset + i, road_col=20 + 40 * i)
        ids[:, 140 + 12 * i: 160 + 12 * i] = CLASS_IDS["road"]
        write_sample(root, "seq00", f"{i:06d}", ids_to_colors(ids), ids, labels=UAVID)
    return root


@pytest.fixture(scope="module")
def splits(tmp_path_factory):
    root = tmp_path_factory.mktemp("learned")
    return _split(root / "train", 5, 0), _split(root / "val", 4, 100)


@pytest.fixture(scope="module")
def model_file(splits, tmp_path_factory):
    from assurance.fitting.learned_monitor import FeatureSettings, fit_learned_monitor

    train, val = splits
    # bound to the network it reports
    doc = fit_learned_monitor(train, RoadBlindFrame(WW), val=val, features=FeatureSettings(core=CORE))
    out = tmp_path_factory.mktemp("model") / "learned.json"
    out.write_text(json.dumps(doc))
    return out


def test_fit_records_a_plain_json_model_with_what_it_rests_on(model_file):
    from el.monitors.learned import BASE_FEATURES, load_learned_model

    doc = json.loads(model_file.read_text())
    b = doc["body"]
    assert b["features"] == list(BASE_FEATURES) and len(b["coef"]) == len(b["mean"]) == len(BASE_FEATURES)
    assert len(b["training"]["sha256"]) == 64 and b["training"]["unsafe"] > 0 and b["held_out"]["unsafe"] > 0
    assert b["selection"]["held_out_recall"] >= 0.95 and b["C"] in (0.01, 0.1, 1.0, 10.0)
    assert b["sklearn_version"] and "weights" in b and b["mcd"]["n"] == 0
    m = load_learned_model(model_file, labels=UAVID)
    assert m.threshold == b["threshold"] and 0.0 < m.threshold < 1.0


def test_recall_threshold():
    from assurance.fitting.learned_monitor import recall_threshold

    s = np.linspace(0, 1, 101)
    t = recall_threshold(s, np.ones(101, bool), 0.95)
    assert (s > t).mean() >= 0.95 and (s > s[6]).mean() < 0.95
    with pytest.raises(ValueError, match="no truly unsafe"):
        recall_threshold(s, np.zeros(101, bool))


def test_tampered_missing_or_foreign_model_files_are_refused(model_file, tmp_path):
    from el.monitors.learned import LearnedModelError, load_learned_model

    doc = json.loads(model_file.read_text())
    doc["body"]["coef"][0] += 1.0
    bad = tmp_path / "tampered.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(LearnedModelError, match="altered"):
        load_learned_model(bad, labels=UAVID)
    with pytest.raises(LearnedModelError, match="cannot read.*fit-monitor"):
        load_learned_model(tmp_path / "missing.json", labels=UAVID)
    (tmp_path / "x.json").write_text('{"format": "pickle"}')
    with pytest.raises(LearnedModelError, match="not a learned monitor model"):
        load_learned_model(tmp_path / "x.json", labels=UAVID)


def test_features_are_what_the_frame_and_patch_show():
    from el.base.decision import Candidate
    from el.monitors.base import CandidateContext
    from el.monitors.learned import BASE_FEATURES, candidate_features
    from el.monitors.patches import extract_patch

    ids = np.full((64, 64), CLASS_IDS["low_vegetation"], np.uint8)
    ids[:, 40:] = CLASS_IDS["road"]  # road 8 px right of a disc of radius 8 centred at x = 24
    seg = OracleSegmenter(64)
    rgb = ids_to_colors(ids)
    cand = Candidate(0, 24.0, 32.0, 8.0, 0.1, 0.1, 0.1)
    patch = extract_patch(rgb, cand, margin=1.5)
    f = dict(zip(BASE_FEATURES, candidate_features(seg.predict_patch(patch.rgb), patch,
                                                   CandidateContext(cand, seg.predict_frame(rgb), (64, 64)),
                                                   margin=1.5, labels=UAVID), strict=True))
    assert f["hd_forbidden_fraction"] == 0 and f["lr_forbidden_fraction"] == 0 and f["hd_max_margin"] < 0
    assert f["edge_distance_radii"] == pytest.approx(np.hypot(40.5 - 24, 0.5) / 8 - 1)
    assert f["row"] == 0.5 and f["radius"] == 8 / 64 and f["hazard"] == 0.1
    # Context: the road starts 8 px (one radius) beyond the disc's edge, so only the 3-radii disc reaches it.
    assert f["ctx1.5_max_forbidden_p"] == 0 and f["ctx2_max_forbidden_p"] == 0
    assert f["ctx3_max_forbidden_p"] == pytest.approx(1) and 0 < f["ctx3_mean_forbidden_p"] < 0.5
    assert f["hd_max_p_road"] == 0 and f["lr_max_p_road"] == 0 and f["hd_max_p_building"] == 0
    ids[28:36, 20:28] = CLASS_IDS["static_car"]  # a car in the disc
    rgb = ids_to_colors(ids)
    patch = extract_patch(rgb, cand, margin=1.5)
    g = dict(zip(BASE_FEATURES, candidate_features(seg.predict_patch(patch.rgb), patch,
                                                   CandidateContext(cand, seg.predict_frame(rgb), (64, 64)),
                                                   margin=1.5, labels=UAVID), strict=True))
    assert g["hd_max_p_static_car"] == 1 and g["lr_max_p_static_car"] == pytest.approx(1)
    assert g["ctx1.5_max_forbidden_p"] == pytest.approx(1) and g["hd_max_p_road"] == 0


def test_a_model_on_a_subset_of_the_features_still_loads_and_unknown_ones_are_refused(model_file, tmp_path):
    from el.monitors.learned import BASE_FEATURES, CORE_FEATURES, LearnedModelError, load_learned_model, model_document

    body = json.loads(model_file.read_text())["body"]
    full = load_learned_model(model_file, labels=UAVID)
    x = np.linspace(0.0, 1.0, len(BASE_FEATURES))
    keep = [BASE_FEATURES.index(n) for n in CORE_FEATURES]  # a model fitted before the context features
    old = dict(body, features=list(CORE_FEATURES), **{k: [body[k][i] for i in keep] for k in ("mean", "scale", "coef")})
    path = tmp_path / "old.json"
    path.write_text(json.dumps(model_document(old)))
    m = load_learned_model(path, labels=UAVID)
    z = ((x[keep] - full.mean[keep]) / full.scale[keep]) @ full.coef[keep] + full.intercept
    assert m.predict(x) == pytest.approx(1 / (1 + np.exp(-z)))
    with pytest.raises(ValueError, match="expected candidate feature vectors"):
        m.predict(x[keep])
    for names, needle in ((["no_such_feature"] + list(CORE_FEATURES[1:]), "'no_such_feature'.*not among"),
                          (list(CORE_FEATURES[:1]) * 12, "listed twice"), ([], "empty")):
        path.write_text(json.dumps(model_document(dict(old, features=names))))
        with pytest.raises(LearnedModelError, match=needle):
            load_learned_model(path, labels=UAVID)


def test_pipeline_uses_it_by_name_and_a_bad_file_is_the_default_action(model_file, splits, tmp_path):
    from el.flight.pipeline import EmergencyLanding, PipelineConfig

    _, val = splits
    image = next(val.glob("**/Images/*.png"))
    seg = RoadBlindFrame(WW)
    spec = f"learned:model={model_file}"
    d = EmergencyLanding(PipelineConfig(core=CORE, monitor=spec, evaluate_all=True, time_budget_s=None),
                         segmenter=seg).decide(image)
    assert not d.reason.startswith("fault"), d.reason
    assert d.candidates and all(c.monitor.name == spec and 0 <= c.monitor.score <= 1 for c in d.candidates)
    assert all(c.monitor.accepted == (c.monitor.score <= c.monitor.threshold) for c in d.candidates)
    doc = json.loads(model_file.read_text())
    doc["body"]["threshold"] = 1.0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    for path, needle in ((bad, "altered"), (tmp_path / "none.json", "cannot read")):
        d = EmergencyLanding(PipelineConfig(core=CORE, monitor=f"learned:model={path}"), segmenter=seg).decide(image)
        assert d.action == "default" and d.reason.startswith("fault: monitor") and needle in d.reason


def test_cli_fit_monitor_and_land_fail_loud(splits, tmp_path, capsys, monkeypatch):
    import el.segmentation as seg_module
    from assurance.cli import main

    train, val = splits
    monkeypatch.setattr(seg_module.Segmenter, "load", classmethod(lambda cls, *a, **k: RoadBlindFrame(WW)))
    out = tmp_path / "m.json"
    assert main(["fit-monitor", "--data", str(train), "--val", str(val), "--out", str(out),
                 "--working-width", str(WW)]) == 0, capsys.readouterr().err
    assert "held-out AUROC" in capsys.readouterr().out
    assert json.loads(out.read_text())["body"]["weights"]["sha256"] == RoadBlindFrame.weights_sha256  # its own
    assert main(["fit-monitor", "--data", str(tmp_path / "nope"), "--out", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    for recall in ("1", "nan"):  # refused by the selection's own check, the one fit-verifier's options share
        assert main(["fit-monitor", "--data", str(train), "--val", str(val), "--out", str(out),
                     "--recall", recall]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "recall must lie in (0, 1)" in err[0]
    image = next(val.glob("**/Images/*.png"))
    assert main(["land", str(image), "--monitor", f"learned:model={tmp_path / 'none.json'}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.json" in err[0]


def test_campaign_and_calibration_by_name(model_file, splits, tmp_path):
    from assurance.campaign import readouts
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign
    from assurance.fitting.calibration import CalibrationScenes, ThresholdRule, calibrate_on_data

    _, val = splits
    spec = f"learned:model={model_file}"
    config = CampaignConfig(perturbations=("none",), monitors=("lhd", spec), core=CORE)
    summary = run_campaign(val, tmp_path / "run", config, segmenter=RoadBlindFrame(WW),
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    cands = readouts.load_table(tmp_path / "run", "candidates")
    mine = cands[cands["monitor"] == spec]
    assert len(mine) and mine["score"].between(0, 1).all()
    doc = calibrate_on_data(val, spec, rule=ThresholdRule(miss_rate=0.3, confidence=0.7),
                            scenes=CalibrationScenes(core=CORE), segmenter=RoadBlindFrame(WW))
    assert doc["body"]["monitor"] == spec and doc["body"]["spec"].startswith(spec + ",threshold=")


def test_card_run_and_monitor_must_rest_on_the_same_learned_model(model_file, splits, tmp_path):
    """A threshold calibrated on one learned model is refused on another: in flight (default action), at the
    campaign (resuming with another model), and by EL-R16 (the run scored with another model)."""
    from assurance.campaign import readouts
    from assurance.campaign.run import CampaignConfig, plan, run_campaign, run_task
    from assurance.fitting.calibration import CalibrationScenes, ThresholdRule, calibrate_on_data
    from assurance.requirements.calibration_check import check_calibrated_miss_rate
    from el.flight.pipeline import EmergencyLanding, PipelineConfig
    from el.monitors.calibration import load_calibration
    from el.monitors.learned import load_learned_model, model_document

    _, val = splits
    spec = f"learned:model={model_file}"
    card_path = tmp_path / "card.json"
    card_path.write_text(json.dumps(calibrate_on_data(val, spec, rule=ThresholdRule(miss_rate=0.3, confidence=0.7),
                                                      scenes=CalibrationScenes(core=CORE),
                                                      segmenter=RoadBlindFrame(WW))))
    card = load_calibration(card_path)
    assert card.body["monitor_model"]["sha256"] == load_learned_model(model_file, labels=UAVID).sha256
    run = tmp_path / "run"
    config = CampaignConfig(perturbations=("none",), monitors=(spec,), core=CORE)
    assert run_campaign(val, run, config, segmenter=RoadBlindFrame(WW),
                        execution=Execution(progress=False))["faults"] == []
    assert readouts.read_manifest(run)["monitor_models"] == {spec: card.body["monitor_model"]["sha256"]}
    cands = readouts.load_table(run, "candidates")
    models = readouts.read_manifest(run)["monitor_models"]
    same = check_calibrated_miss_rate(cands, card, run_models=models)
    assert same.rows and "unsafe candidates accepted" in same.summary  # judged on its miss rate

    assert check_calibrated_miss_rate(cands, card, run_models=None).status == "insufficient"  # an older run

    # Refit in place (another model under the same path): the card, the run and the monitor no longer agree.
    body = json.loads(model_file.read_text())["body"]
    other = tmp_path / "learned.json"
    other.write_text(json.dumps(model_document(dict(body, intercept=body["intercept"] + 0.5))))
    foreign = check_calibrated_miss_rate(cands, card, run_models={spec: load_learned_model(other, labels=UAVID).sha256})
    assert foreign.status == "fail" and "calibrated on monitor model" in foreign.summary
    image = next(val.glob("**/Images/*.png"))
    original = model_file.read_text()
    try:
        model_file.write_text(other.read_text())
        d = EmergencyLanding(PipelineConfig(core=CORE, monitor=spec, calibration=str(card_path)),
                             segmenter=RoadBlindFrame(WW)).decide(image)
        assert d.action == "default" and "recalibrate" in d.reason, d.reason
        with pytest.raises(readouts.RunError, match="monitor_models"):
            run_campaign(val, run, config, segmenter=RoadBlindFrame(WW), execution=Execution(progress=False))
        # A model file that changes while a run goes on: the task is a fault, not a mix of two models.
        task = plan(val, config)[0]
        rows = run_task(task, config, RoadBlindFrame(WW), expected_models=models)
        assert "its model file changed during the run" in rows["images"][0]["fault"]
    finally:
        model_file.write_text(original)
    d = EmergencyLanding(PipelineConfig(core=CORE, monitor=spec, calibration=str(card_path)),
                         segmenter=RoadBlindFrame(WW)).decide(image)
    assert not d.reason.startswith("fault"), d.reason


def test_context_windows_give_what_the_whole_frame_gives():
    """The context statistics are read from a window around the candidate: the same numbers, bit for bit,
    as masking the whole frame (discs near the border, and smaller than a working pixel, included)."""
    from feature_reference import frame_disc_mask

    from el.base.decision import Candidate, Disc
    from el.monitors.learned import _FORBIDDEN, CONTEXT_SCALES, frame_features
    from el.monitors.lhd import take_disc

    rng = np.random.default_rng(3)
    frame = rng.random((8, 36, 64)).astype(np.float32)
    frame /= frame.sum(axis=0)
    scale = 64 / 256
    for _ in range(60):
        cand = Candidate(0, float(rng.uniform(0, 256)), float(rng.uniform(0, 144)), float(rng.uniform(0.5, 60)),
                         0.1, 0.1, 0.1)
        want = []
        for k in CONTEXT_SCALES:
            mask = frame_disc_mask(frame.shape[1:], Disc(cand.x, cand.y, cand.radius_px * k), scale)
            p = take_disc(frame, mask)[_FORBIDDEN].astype(np.float64).sum(axis=0)
            want += [float(p.max()), float(p.mean())]
        assert frame_features(frame, cand, scale, UAVID)[1] == want


def test_a_run_recorded_before_monitor_models_is_not_resumed_with_a_learned_monitor(model_file, splits, tmp_path):
    from assurance.campaign import readouts
    from assurance.campaign.run import CampaignConfig, run_campaign

    _, val = splits
    config = CampaignConfig(perturbations=("none",), monitors=(f"learned:model={model_file}",), core=CORE,
                            images=1)
    run = tmp_path / "run"
    run_campaign(val, run, config, segmenter=RoadBlindFrame(WW), execution=Execution(progress=False))
    man = json.loads((run / "manifest.json").read_text())
    del man["monitor_models"]  # as a run of an earlier version recorded it
    (run / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(readouts.RunError, match="not recorded"):
        run_campaign(val, run, config, segmenter=RoadBlindFrame(WW), execution=Execution(progress=False))


def test_the_deployed_default_is_checked_against_the_deployed_card(splits, tmp_path, monkeypatch):
    """Without --calibration, the deployed spec runs the deployed card's threshold: a swapped model file
    under the default path makes every decision the default action, with the reason."""
    import el.monitors.learned as learned
    from el.flight.pipeline import EmergencyLanding, PipelineConfig
    from el.monitors.learned import DEFAULT_MODEL, model_document

    _, val = splits
    image = next(val.glob("**/Images/*.png"))
    body = json.loads(DEFAULT_MODEL.read_text())["body"]
    swapped = tmp_path / "learned.json"
    swapped.write_text(json.dumps(model_document(dict(body, intercept=body["intercept"] - 1.0))))
    from el.segmentation.weights import DEFAULT_WEIGHTS, read_card

    config = PipelineConfig(core=CORE, time_budget_s=None)
    shipped = RoadBlindFrame(WW)
    shipped.weights_sha256 = read_card(DEFAULT_WEIGHTS)["weights_sha256"]  # as the shipped network reports
    assert not EmergencyLanding(config, segmenter=shipped).fault
    assert "fitted on network" in EmergencyLanding(config, segmenter=RoadBlindFrame(WW)).fault  # no hash: refused
    monkeypatch.setattr(learned, "DEFAULT_MODEL", swapped)
    d = EmergencyLanding(config, segmenter=shipped).decide(image)
    # the deployed verifier pins the learned model it is fused with; a plain learned spec, its card's model
    assert d.action == "default" and d.reason.startswith("fault: monitor") and "fused with learned model" in d.reason
    alone = PipelineConfig(core=CORE, time_budget_s=None, monitor="learned:walk=score",
                           calibration=str(DEFAULT_MODEL.with_name("learned_calibration.json")))
    d = EmergencyLanding(alone, segmenter=shipped).decide(image)
    assert d.action == "default" and d.reason.startswith("fault: monitor") and "recalibrate" in d.reason


def test_a_card_with_a_malformed_model_record_is_refused(tmp_path):
    from el.flight.pipeline import DEPLOYED_CALIBRATION
    from el.monitors.calibration import CalibrationError, card_document, load_calibration

    body = json.loads(DEPLOYED_CALIBRATION.read_text())["body"]
    for bad in ("ead9566c", {"sha256": "XYZ"}, {"sha256": 5}):
        path = tmp_path / "card.json"
        path.write_text(json.dumps(card_document(dict(body, monitor_model=bad))))
        with pytest.raises(CalibrationError, match="monitor_model must be"):
            load_calibration(path)


@pytest.mark.parametrize("kw, match", [({"recall": 0.0}, "recall"), ({"recall": float("nan")}, "recall"),
                                       ({"cs": ()}, "L2"), ({"cs": (1.0, -0.1)}, "L2")])
def test_a_selection_out_of_range_is_refused(kw, match):
    from assurance.fitting.learned_monitor import Selection

    with pytest.raises(ValueError, match=match):
        Selection(**kw)

