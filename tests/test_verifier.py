"""The candidate verifier (``el.monitors.verifier``): its crop, its record and ONNX network, its verdicts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from el.base.decision import Disc
from el.base.errors import LearnedModelError
from el.classes.labels import UAVID
from el.monitors import build_monitor, monitor_names
from el.monitors.verifier import VerifierMonitor, fused_score, load_verifier, logit
from el.monitors.verifier_crop import candidate_crop, crop_disc_mask, crop_window

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")


def test_crop_is_the_disc_and_its_margin_at_a_fixed_size():
    img = np.zeros((200, 300, 3), np.uint8)
    img[:, 150:] = 255  # right half white
    crop = candidate_crop(img, Disc(150.0, 100.0, 20.0), size=16, margin=0.5)
    assert crop.shape == (16, 16, 3) and crop.dtype == np.uint8
    assert crop[:, :7].max() == 0 and crop[:, 9:].min() == 255  # the white edge runs down the middle
    assert crop_window(Disc(150.0, 100.0, 20.0), 0.5) == (120, 70, 180, 130)
    # outside the image is black (the border counts as forbidden)
    corner = candidate_crop(np.full((50, 50, 3), 200, np.uint8), Disc(2.0, 2.0, 10.0), size=16, margin=0.0)
    assert corner[0, 0].max() == 0 and corner[-1, -1].min() == 200
    mask = crop_disc_mask(16, 0.5)
    assert mask[8, 8] and not mask[0, 0] and mask.sum() == pytest.approx(np.pi * (16 / 3) ** 2, rel=0.1)
    with pytest.raises(ValueError, match="outside"):
        candidate_crop(img, Disc(900.0, 100.0, 5.0), size=16, margin=0.5)
    with pytest.raises(ValueError, match="size"):
        candidate_crop(img, Disc(100.0, 100.0, 5.0), size=4, margin=0.5)


def test_fusion_is_a_weighted_sum_of_logits():
    pv, pl = np.array([0.9, 0.1]), np.array([0.5, 0.5])
    assert fused_score(pv, pl, 1.0) == pytest.approx(pv)
    assert fused_score(pv, pl, 0.0) == pytest.approx(pl)
    assert fused_score(pv, pl, 0.5) == pytest.approx(1 / (1 + np.exp(-0.5 * logit(pv))))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> tuple[Path, object]:
    """A tiny verifier network (random weights), exported and recorded as fit-verifier records one."""
    from assurance.fitting.verifier_fit import export_onnx, write_verifier
    from assurance.fitting.verifier_net import VerifierNet
    from el.base.hashing import sha256_bytes

    torch.manual_seed(0)
    net = VerifierNet(size=32, margin=0.5, width=8).eval()
    onnx = export_onnx(net)
    out = tmp_path_factory.mktemp("verifier") / "v.json"
    body = {"onnx": {"file": "v.onnx", "sha256": sha256_bytes(onnx)}, "crop": {"size": 32, "margin": 0.5},
            "threshold": 0.5, "weights": {"sha256": "abc"}}
    write_verifier(out, body, onnx)
    return out, net


def test_monitor_scores_a_frame_in_one_batch_as_torch_does(tiny):
    from assurance.fitting.verifier_train import predict

    path, net = tiny
    assert "verifier" in monitor_names()
    m = build_monitor(f"verifier:model={path}", labels=UAVID)
    assert isinstance(m, VerifierMonitor) and m.name == f"verifier:model={path}" and m.threshold == 0.5
    img = np.random.default_rng(0).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    discs = [Disc(40.0, 40.0, 10.0), Disc(150.0, 110.0, 12.0), Disc(80.0, 60.0, 6.0)]
    verdicts = m.check_many(img, discs, None, seeds=[0, 1, 2])
    want = predict(net, m.crops(img, discs))
    assert [v.score for v in verdicts] == pytest.approx(want, abs=1e-5)
    assert all(v.accepted == (v.score <= 0.5) for v in verdicts)
    one = m.check(img, discs[1], None, seed=1)
    assert one.score == pytest.approx(verdicts[1].score, abs=1e-6)
    t = build_monitor(f"verifier:model={path},threshold=0.25", labels=UAVID)
    assert t.name.endswith("threshold=0.25")


def test_fitting_scores_held_out_crops_with_the_session_that_flies(tiny):
    import pickle

    from assurance.fitting.verifier_fit import onnx_probabilities

    path, _ = tiny
    m = VerifierMonitor(labels=UAVID, model=str(path))
    crops = np.random.default_rng(1).integers(0, 256, (5, 32, 32, 3), dtype=np.uint8)
    at_once = m.session.probabilities(crops)
    assert onnx_probabilities(load_verifier(path).onnx, crops, batch=2) == pytest.approx(at_once, abs=1e-6)
    again = pickle.loads(pickle.dumps(m.session))  # campaign workers get it pickled
    assert again.probabilities(crops) == pytest.approx(at_once, abs=1e-6) and again.source == m.session.source
    assert m.session.probabilities(crops[:0]).shape == (0,)
    with pytest.raises(ValueError, match="uint8"):
        m.session.probabilities(crops.astype(np.float32))


def test_record_and_network_are_checked(tiny, tmp_path):
    path, _ = tiny
    assert load_verifier(path).size == 32
    doc = json.loads(path.read_text())
    doc["body"]["threshold"] = 0.9  # altered body
    bad = tmp_path / "v.json"
    bad.write_text(json.dumps(doc))
    (tmp_path / "v.onnx").write_bytes((path.parent / "v.onnx").read_bytes())
    with pytest.raises(LearnedModelError, match="altered"):
        load_verifier(bad)
    other = tmp_path / "other"
    other.mkdir()
    (other / "v.json").write_text(path.read_text())
    (other / "v.onnx").write_bytes(b"not the network")
    with pytest.raises(LearnedModelError, match="SHA-256"):
        load_verifier(other / "v.json")
    with pytest.raises(ValueError, match="fuse"):
        VerifierMonitor(labels=UAVID, model=str(path), fuse="lhd")
    with pytest.raises(LearnedModelError, match="fusion"):
        VerifierMonitor(labels=UAVID, model=str(path), fuse="learned")  # no fusion recorded


def test_verifier_refuses_another_network(tiny):
    path, _ = tiny
    m = VerifierMonitor(labels=UAVID, model=str(path))

    class Net:
        weights_sha256 = "def"

    with pytest.raises(LearnedModelError, match="refit"):
        m.check_network(Net())


def test_the_shipped_verifier_is_bound_to_the_shipped_network_and_learned_model():
    from el.monitors.learned import load_learned_model
    from el.segmentation.weights import DEFAULT_WEIGHTS, read_card

    record = load_verifier()
    assert record.size == 256 and record.body["weights"]["sha256"] == read_card(DEFAULT_WEIGHTS)["weights_sha256"]
    assert record.body["held_out"]["candidates"] > 0 and record.body["training"]["sha256"]
    fused = VerifierMonitor(labels=UAVID, fuse="learned")
    assert fused.name == "verifier:fuse=learned"
    assert record.fusion["learned_sha256"] == load_learned_model(None, labels=UAVID).sha256
    img = np.random.default_rng(3).integers(0, 256, (300, 400, 3), dtype=np.uint8)
    v = build_monitor("verifier", labels=UAVID).check_many(img, [Disc(200.0, 150.0, 40.0)], None, seeds=[0])
    assert 0.0 <= v[0].score <= 1.0


def test_the_shipped_verifier_card_is_calibrated_on_the_shipped_verifier():
    from el.monitors.calibration import load_calibration

    card_path = Path(load_verifier().path).parent / "verifier_calibration.json"
    card = load_calibration(card_path)
    assert card.body["monitor"] == "verifier:walk=score"
    assert card.body["monitor_model"]["sha256"] == load_verifier().sha256
    assert card.body["split"]["path"] == "data/val" and card.body["miss_rate"] == 0.8
