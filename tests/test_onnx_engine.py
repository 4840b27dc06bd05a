"""ONNX Runtime as the engine of a project network: the committed export of the shipped network matches its
weights, the engine is chosen (and refused) as documented, MC dropout stays on torch with the same numbers."""

from __future__ import annotations

import json
import pickle
import shutil

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from helpers import TINY_ARCH  # noqa: E402

from assurance.fitting.network.onnx_export import check_frame, export_onnx  # noqa: E402
from assurance.fitting.network.weights_io import save_weights  # noqa: E402
from el.base.errors import WeightsError  # noqa: E402
from el.base.hashing import sha256_file  # noqa: E402
from el.segmentation.architectures import build_model  # noqa: E402
from el.segmentation.inference import Segmenter  # noqa: E402
from el.segmentation.onnx_engine import ENGINE_ENV, RECORD_FORMAT, record_path  # noqa: E402
from el.segmentation.onnx_model import META_SOURCE, load_onnx_model  # noqa: E402
from el.segmentation.weights import DEFAULT_WEIGHTS, read_card  # noqa: E402

SHIPPED_ONNX = DEFAULT_WEIGHTS.with_suffix(".onnx")


def _load(monkeypatch, engine, path=None, **kw):
    monkeypatch.setenv(ENGINE_ENV, engine)
    return Segmenter.load(path, **kw)


def same_argmax(probs, ref, tie=1e-4):
    top2 = np.sort(ref, axis=0)[-2:]
    return int(((probs.argmax(0) != ref.argmax(0)) & (top2[1] - top2[0] > tie)).sum()) == 0


def test_the_committed_export_is_the_shipped_network(monkeypatch):
    """Hashes bound (record, card, file, metadata) and the same segmentation as torch on a frame and a patch."""
    record = json.loads(record_path(DEFAULT_WEIGHTS).read_text())
    assert record["format"] == RECORD_FORMAT and record["onnx_sha256"] == sha256_file(SHIPPED_ONNX)
    assert record["weights_sha256"] == read_card(DEFAULT_WEIGHTS)["weights_sha256"] == sha256_file(DEFAULT_WEIGHTS)
    assert SHIPPED_ONNX.stat().st_size < 20 * 2**20
    loaded = load_onnx_model(SHIPPED_ONNX, sha256=record["onnx_sha256"])  # loads with no configuration
    assert loaded.weights_sha256 == record["onnx_sha256"]
    torch_seg = _load(monkeypatch, "torch", threads=1)
    onnx_seg = _load(monkeypatch, "onnx", threads=1)
    assert torch_seg.engine_name == "torch" and onnx_seg.engine_name == "onnx"
    assert onnx_seg.weights_sha256 == torch_seg.weights_sha256  # the same network: cards and monitors still bind
    frame = check_frame(None, 1024)
    a, b = onnx_seg.predict_frame(frame), torch_seg.predict_frame(frame)
    assert np.abs(a - b).max() < 1e-4 and same_argmax(a, b)
    patch = np.ascontiguousarray(frame[300:461, 500:707])
    a, b = onnx_seg.predict_patch(patch), torch_seg.predict_patch(patch)
    assert np.abs(a - b).max() < 1e-4 and same_argmax(a, b)
    assert loaded._session.get_modelmeta().custom_metadata_map[META_SOURCE] == record["weights_sha256"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny project network with its ONNX export and engine record beside it."""
    import torch

    torch.manual_seed(0)
    folder = tmp_path_factory.mktemp("tiny")
    weights = folder / "tiny.pt"
    save_weights(build_model(TINY_ARCH), weights)
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 255, (72, 128, 3), dtype=np.uint8)
    export_onnx(str(weights), weights.with_suffix(".onnx"), frame=frame, beside=True)
    return weights, frame


def test_engine_choice(tiny, monkeypatch):
    weights, frame = tiny
    assert _load(monkeypatch, "auto", weights, working_width=64).engine_name == "onnx"
    assert _load(monkeypatch, "torch", weights, working_width=64).engine_name == "torch"
    with pytest.raises(WeightsError, match=ENGINE_ENV):
        _load(monkeypatch, "tensorrt", weights)


def test_a_stale_or_altered_export_is_never_run(tiny, tmp_path, monkeypatch):
    weights, _ = tiny
    for name in ("tiny.pt", "tiny.json", "tiny.onnx", "tiny.onnx.json"):
        shutil.copy(weights.parent / name, tmp_path / name)
    copy = tmp_path / "tiny.pt"
    data = bytearray(copy.with_suffix(".onnx").read_bytes())
    data[-1] ^= 1
    copy.with_suffix(".onnx").write_bytes(bytes(data))
    assert _load(monkeypatch, "auto", copy).engine_name == "torch"  # auto: torch, the reference, with a warning
    with pytest.raises(WeightsError, match="SHA-256 mismatch"):
        _load(monkeypatch, "onnx", copy)
    rec = json.loads(record_path(copy).read_text())
    record_path(copy).write_text(json.dumps({**rec, "weights_sha256": "0" * 64}))
    with pytest.raises(WeightsError, match="export it again"):
        _load(monkeypatch, "onnx", copy)
    record_path(copy).unlink()
    assert _load(monkeypatch, "auto", copy).engine_name == "torch"


def test_mc_dropout_runs_its_head_on_the_onnx_trunk(tiny, monkeypatch):
    """One ONNX Runtime pass gives a patch's softmax and the trunk that MC dropout's torch head runs on: the
    same samples as torch's to float rounding."""
    weights, frame = tiny
    onnx_seg = _load(monkeypatch, "onnx", weights, working_width=64)
    torch_seg = _load(monkeypatch, "torch", weights, working_width=64)
    assert onnx_seg.engine.trunk_names  # the export carries the trunk
    patch = np.ascontiguousarray(frame[3:40, 5:61])
    shared = onnx_seg.patch_trunk(patch)  # lazy: nothing computed yet
    assert shared.value is None and shared.logits is None
    np.testing.assert_allclose(onnx_seg.predict_patch(patch, features=shared), torch_seg.predict_patch(patch),
                               atol=1e-5)
    assert shared.value is not None  # the same pass gave the trunk
    a = onnx_seg.mc_dropout(patch, 4, 0.9, 11, features=shared)
    b = torch_seg.mc_dropout(patch, 4, 0.9, 11, features=torch_seg.patch_trunk(patch))
    np.testing.assert_allclose(a, b, atol=1e-5)
    np.testing.assert_allclose(onnx_seg.mc_dropout(patch, 4, 0.9, 11, window=(2, 30, 4, 50)),
                               b[:, :, 2:30, 4:50], atol=1e-5)
    again = pickle.loads(pickle.dumps(onnx_seg))  # worker processes
    assert again.engine_name == "onnx"
    np.testing.assert_array_equal(again.predict_frame(frame), onnx_seg.predict_frame(frame))
