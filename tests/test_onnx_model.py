"""A network from elsewhere as ONNX: export, every contract variant, refusals at load, the factory."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from helpers import scene_ids  # noqa: E402
from onnx_helpers import MEAN, STD, ColourNet, Variant, export_raw, noisy_colours  # noqa: E402

from assurance.cli import main  # noqa: E402
from assurance.fitting.network.onnx_export import export_onnx  # noqa: E402
from el.base.errors import WeightsError  # noqa: E402
from el.base.hashing import sha256_file  # noqa: E402
from el.classes.labels import UAVID  # noqa: E402
from el.segmentation.factory import load_model  # noqa: E402
from el.segmentation.inference import Segmenter  # noqa: E402
from el.segmentation.onnx_model import META_CONTRACT, OnnxContract, OnnxModel, load_onnx_model  # noqa: E402

NAMES = list(UAVID.names)
FRAME = noisy_colours(scene_ids(128, 72, seed=3))


@pytest.fixture(scope="module")
def native():
    return Segmenter(ColourNet(), working_width=64, card={"weights_sha256": "ab" * 32}, labels=UAVID)


@pytest.fixture(scope="module")
def exported(native, tmp_path_factory):
    path = tmp_path_factory.mktemp("onnx") / "colour.onnx"
    result = export_onnx(native, path, frame=FRAME)
    return path, result


def test_export_writes_metadata_and_matches_torch(exported, native):
    path, result = exported
    assert result["sha256"] == sha256_file(path) and result["opset"] == 17
    assert result["source_weights_sha256"] == "ab" * 32 and result["classes"] == NAMES
    assert all(c["argmax_differ_not_tie"] == 0 and c["max_logit_diff"] < 1e-3 for c in result["checks"])
    model = load_onnx_model(path, working_width=64)  # no configuration: the contract is in the file
    assert model.contract == OnnxContract(class_names=tuple(NAMES)) and model.weights_sha256 == result["sha256"]
    for probs, ref in ((model.predict_frame(FRAME), native.predict_frame(FRAME)),
                       (model.predict_patch(FRAME[5:42, 7:60]), native.predict_patch(FRAME[5:42, 7:60]))):
        assert probs.shape == ref.shape and probs.dtype == np.float32
        np.testing.assert_allclose(probs, ref, atol=1e-5)
        assert same_argmax(probs, ref)


def same_argmax(probs, ref, tie=1e-4):
    """Argmax identical on every pixel but float ties (native top-two gap below ``tie``)."""
    top2 = np.sort(ref, axis=0)[-2:]
    return not ((probs.argmax(0) != ref.argmax(0)) & (top2[1] - top2[0] > tie)).any()


def test_load_model_dispatches_onnx_files(exported):
    path, result = exported
    model = load_model(str(path), working_width=64)
    assert isinstance(model, OnnxModel) and model.weights_sha256 == result["sha256"]
    assert model.predict_frame(FRAME).shape == (8, 36, 64)


VARIANTS = {
    "bgr": ({"bgr": True}, {"channel_order": "bgr"}),
    "nhwc": ({"nhwc": True}, {"layout": "nhwc"}),
    "mean_std": ({"mean_std": True}, {"scaling": "mean_std", "mean": MEAN, "std": STD, "value_range": 255}),
    "probabilities": ({"probabilities": True}, {"output": "probabilities"}),
    "permuted": ({"order": [7, 6, 5, 4, 3, 2, 1, 0]}, {"class_names": NAMES[::-1]}),
    "all": ({"bgr": True, "nhwc": True, "mean_std": True, "probabilities": True},
            {"channel_order": "bgr", "layout": "nhwc", "scaling": "mean_std", "mean": MEAN, "std": STD,
             "value_range": 255, "output": "probabilities"}),
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_every_contract_variant_gives_the_native_answer(name, native, tmp_path):
    module_kw, contract_kw = VARIANTS[name]
    path = tmp_path / f"{name}.onnx"
    export_raw(Variant(ColourNet(), **module_kw), path, nhwc=module_kw.get("nhwc", False))
    contract = OnnxContract.from_dict({"class_names": NAMES, **contract_kw})
    model = load_onnx_model(path, contract=contract, labels=UAVID, working_width=64)
    np.testing.assert_allclose(model.predict_frame(FRAME), native.predict_frame(FRAME), atol=2e-5)
    np.testing.assert_allclose(model.predict_patch(FRAME[:40, :50]), native.predict_patch(FRAME[:40, :50]), atol=2e-5)
    assert OnnxContract.from_dict(json.loads(json.dumps(contract.to_dict()))) == contract


def test_fixed_and_multiple_size_rules(tmp_path, native):
    static = tmp_path / "static.onnx"
    export_raw(ColourNet(), static, static=(32, 48))
    with pytest.raises(WeightsError, match="refused"):  # the probe at 32x32 does not fit a 48x32 graph
        load_onnx_model(static, contract={"class_names": NAMES}, working_width=64)
    fixed = load_onnx_model(static, contract={"class_names": NAMES, "size": "fixed", "fixed_size": [48, 32]},
                            working_width=64)
    assert fixed.predict_frame(FRAME).shape == (8, 36, 64) and fixed.predict_patch(FRAME[:21, :33]).shape == (8, 21, 33)
    dynamic = tmp_path / "dynamic.onnx"
    export_raw(ColourNet(), dynamic)
    multiple = load_onnx_model(dynamic, contract={"class_names": NAMES, "size": "multiple", "multiple": 16})
    probs = multiple.predict_patch(FRAME[:21, :33])
    assert probs.shape == (8, 21, 33)  # padded to 32x48 for the network, cropped back
    inner = native.predict_patch(FRAME[:21, :33])[:, :20, :32]
    np.testing.assert_allclose(probs[:, :20, :32], inner, atol=2e-5)  # edge padding changes only the last row/column


@pytest.mark.parametrize(("kw", "contract", "match"), [
    ({"drop": True}, {}, "expected 8 class channels"),
    ({"nan": True}, {}, "non-finite"),
    ({}, {"class_names": NAMES[:-1] + ["boat"]}, "not the label set"),
    ({}, {"class_names": NAMES[:-1]}, "not the label set"),
])
def test_unusable_networks_are_refused_at_load(kw, contract, match, tmp_path):
    path = tmp_path / "bad.onnx"
    export_raw(Variant(ColourNet(), **kw), path)
    with pytest.raises(WeightsError, match=match) as err:
        load_onnx_model(path, contract={"class_names": NAMES, **contract}, labels=UAVID)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_hash_and_missing_contract_are_refused(exported, tmp_path):
    path, result = exported
    with pytest.raises(WeightsError, match=f"file has {result['sha256']}, expected {'0' * 64}"):
        load_onnx_model(path, sha256="0" * 64)
    assert load_onnx_model(path, sha256=result["sha256"]).weights_sha256 == result["sha256"]
    bare = tmp_path / "bare.onnx"
    export_raw(ColourNet(), bare)
    with pytest.raises(WeightsError, match=META_CONTRACT):
        load_onnx_model(bare)


def test_contract_validation_names_the_key():
    with pytest.raises(ValueError, match="unknown keys"):
        OnnxContract.from_dict({"class_names": NAMES, "colour": "rgb"})
    with pytest.raises(ValueError, match="layout"):
        OnnxContract(class_names=tuple(NAMES), layout="chw")
    with pytest.raises(ValueError, match="std"):
        OnnxContract(class_names=tuple(NAMES), scaling="mean_std", mean=(0, 0, 0), std=(1, 0, 1))
    with pytest.raises(ValueError, match="multiple"):
        OnnxContract(class_names=tuple(NAMES), size="multiple")
    with pytest.raises(ValueError, match="class_names"):
        OnnxContract.from_dict({"size": "any"})


def test_onnx_model_pickles(exported):
    import pickle

    model = load_onnx_model(exported[0], working_width=64)
    again = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(again.predict_frame(FRAME), model.predict_frame(FRAME))


def test_missing_onnxruntime_is_one_line(monkeypatch, exported):
    import builtins

    real = builtins.__import__

    def no_ort(name, *args, **kwargs):
        if name == "onnxruntime":
            raise ImportError("no onnxruntime")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ort)
    with pytest.raises(WeightsError, match=r"pip install 'uav-el-assurance\[onnx\]'"):
        load_onnx_model(exported[0])


def test_export_onnx_command(tmp_path, capsys):
    """The shipped network through the command: file, SHA-256, opset and the measured difference."""
    out = tmp_path / "shipped.onnx"
    assert main(["export-onnx", "--out", str(out), "--opset", "17"]) == 0
    text = capsys.readouterr().out
    assert f"sha256:   {sha256_file(out)}" in text and "opset:    17" in text
    assert "largest logit difference" in text and "(0 beyond a float tie)" in text
    assert main(["export-onnx", "--out", str(tmp_path / "x.bin")]) == 2
