"""A user's own ONNX network, exported with plain ``torch.onnx.export`` (its own 6 classes, ImageNet mean/std, no
project metadata), on the semantic_drone label set through a system file: its classes named in ``[model.onnx]
class_names`` (or ``[model] classes``) and mapped with ``[model] class_map``; ``[model] working_width`` honoured;
ONNX external data resolved in the model's folder only and hashed into the pinned identity."""

from __future__ import annotations

import hashlib
import io
import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
onnx = pytest.importorskip("onnx")
torch = pytest.importorskip("torch")

from assurance.system import SystemFileError, load_system  # noqa: E402
from assurance.system.system import System  # noqa: E402
from el.base.errors import WeightsError  # noqa: E402
from el.base.hashing import sha256_file  # noqa: E402
from el.classes.labels import load_label_set  # noqa: E402
from el.segmentation.contract import OutputClasses, labels_of  # noqa: E402
from el.segmentation.onnx_engine import external_identity, file_identity, read_onnx  # noqa: E402
from el.segmentation.onnx_model import META_CONTRACT, load_onnx_model  # noqa: E402

CLASSES = ["ground", "lawn", "street", "building", "person", "water"]
TO_DRONE = {"ground": "dirt", "lawn": "grass", "street": "paved-area", "building": "roof", "person": "person",
            "water": "water"}
DRONE = load_label_set("semantic_drone")
UNREACHABLE = [n for n in DRONE.names if n not in TO_DRONE.values()]
MEAN, STD = [0.485, 0.456, 0.406], [0.229, 0.224, 0.225]
FRAME = (np.random.default_rng(0).random((180, 320, 3)) * 255).astype(np.uint8)


def tiny_net() -> torch.nn.Module:
    """A 2-layer conv net with 6 output channels, fixed seed (the user's "U-Net")."""
    torch.manual_seed(0)
    return torch.nn.Sequential(torch.nn.Conv2d(3, 8, 3, padding=1), torch.nn.ReLU(), torch.nn.Conv2d(8, 6, 1)).eval()


def export(path: Path, *, external: bool = False, meta: dict[str, str] | None = None) -> Path:
    """Plain torch.onnx.export (dynamic H, W); ``external``: the weights in ``weights.bin`` beside the file."""
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(tiny_net(), (torch.rand(1, 3, 32, 48),), buf, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {2: "h", 3: "w"}}, opset_version=17, dynamo=False)
    proto = onnx.load_from_string(buf.getvalue())
    for k, v in (meta or {}).items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = k, v
    if external:
        onnx.save_model(proto, str(path), save_as_external_data=True, all_tensors_to_one_file=True,
                        location="weights.bin", size_threshold=0)
    else:
        path.write_bytes(proto.SerializeToString())
    return path


def system_file(folder: Path, onnx_name: str = "unet.onnx", *, pin: str | None = None, model: str = "",
                onnx_keys: str | None = None) -> Path:
    """A system file on the semantic_drone preset with the network's classes and class map."""
    class_map = ", ".join(f'{k} = "{v}"' for k, v in TO_DRONE.items())
    contract = (f"class_names = {json.dumps(CLASSES)}\n" if onnx_keys is None else onnx_keys) + \
        f'scaling = "mean_std"\nmean = {MEAN}\nstd = {STD}\n'
    text = (f'format = "uav-el-system/1"\n[labels]\npreset = "semantic_drone"\n'
            f'[model]\npath = "{onnx_name}"\nclass_map = {{ {class_map} }}\nunreachable = {json.dumps(UNREACHABLE)}\n'
            + (f'sha256 = "{pin}"\n' if pin else "") + model
            + f"[model.onnx]\n{contract}[monitor]\nspec = \"lhd\"\n")
    path = folder / "uav-el.toml"
    path.write_text(text)
    return path


def system_of(path: Path) -> System:
    return System.build(load_system(path))


def test_own_classes_map_onto_semantic_drone_with_no_metadata(tmp_path):
    export(tmp_path / "unet.onnx")
    assert read_onnx(tmp_path / "unet.onnx").sha256 == sha256_file(tmp_path / "unet.onnx")  # existing pins hold
    system = system_of(system_file(tmp_path, pin=sha256_file(tmp_path / "unet.onnx")))
    seg = system.segmenter()
    assert labels_of(seg) == DRONE and seg.network.labels == OutputClasses("unet.onnx", tuple(CLASSES))
    probs = seg.predict_frame(FRAME)
    assert probs.shape == (DRONE.num_classes, 576, 1024) and probs.dtype == np.float32
    np.testing.assert_allclose(probs.sum(axis=0), 1.0, rtol=1e-5)
    assert not probs[[DRONE.ids[n] for n in UNREACHABLE]].any()
    net = seg.network.predict_frame(FRAME)  # the network's own 6 channels, summed onto their system classes
    np.testing.assert_array_equal(probs[DRONE.ids["roof"]], net[CLASSES.index("building")])


def test_the_classes_key_names_the_channels_too(tmp_path):
    export(tmp_path / "unet.onnx")
    seg = system_of(system_file(tmp_path, model=f"classes = {json.dumps(CLASSES)}\n", onnx_keys="")).segmenter()
    assert labels_of(seg) == DRONE and seg.network.contract.class_names == tuple(CLASSES)
    bad = system_file(tmp_path, model=f"classes = {json.dumps(CLASSES[::-1])}\n")
    with pytest.raises(SystemFileError, match="model.classes") as err:
        load_system(bad)
    assert "\n" not in str(err.value) and "uav-el.toml" in str(err.value)


def test_working_width_is_honoured_and_decisions_do_not_fault(tmp_path):
    from el.flight.pipeline import EmergencyLanding

    export(tmp_path / "unet.onnx")
    system = system_of(system_file(tmp_path, model="working_width = 160\n"))
    assert system.core.working_width == 160
    seg = system.segmenter()
    assert seg.predict_frame(FRAME).shape == (DRONE.num_classes, 90, 160)
    assert system.segmenter(working_width=96).predict_frame(FRAME).shape[2] == 96  # a command's option wins
    landing = EmergencyLanding(system.flight_config(), segmenter=seg)
    assert landing.fault is None
    decision = landing.decide(FRAME)
    assert not decision.reason.startswith("fault"), decision.reason


def test_a_campaign_at_the_working_width_has_no_fault(tmp_path):
    from assurance import cli
    from assurance.campaign import readouts
    from assurance.dataio.uavid import write_sample

    export(tmp_path / "unet.onnx")
    system = system_file(tmp_path, model="working_width = 160\n")
    ids = np.zeros((180, 320), np.uint8)
    ids[:, 160:] = DRONE.ids["grass"]
    write_sample(tmp_path / "data", "seq00", "000000", FRAME, ids, labels=DRONE)
    assert cli.main(["campaign", "--system", str(system), "--data", str(tmp_path / "data"), "--out",
                     str(tmp_path / "run"), "--perturbations", "none", "--monitors", "lhd", "--quiet"]) == 0
    images = readouts.load_table(tmp_path / "run", "images")
    assert (images["fault"] == "").all(), images["fault"].tolist()


def test_without_a_class_map_foreign_classes_are_refused_in_one_line(tmp_path):
    export(tmp_path / "unet.onnx")
    path = system_file(tmp_path)
    path.write_text(path.read_text().replace("class_map", "# class_map").replace("unreachable", "# unreachable"))
    with pytest.raises(WeightsError, match="not the label set 'semantic_drone'") as err:
        system_of(path).segmenter()
    assert "\n" not in str(err.value) and "unet.onnx" in str(err.value)


def test_a_bare_onnx_spec_without_a_label_set_is_refused(tmp_path):
    from el.segmentation.factory import load_model

    contract = {"class_names": CLASSES, "scaling": "mean_std", "mean": MEAN, "std": STD}
    path = export(tmp_path / "meta.onnx", meta={META_CONTRACT: json.dumps(contract)})
    assert isinstance(load_onnx_model(path).labels, OutputClasses)  # no UAVid default: its own classes
    with pytest.raises(WeightsError, match="no label set") as err:
        load_model(str(path))
    assert "\n" not in str(err.value) and "meta.onnx" in str(err.value)


@pytest.mark.parametrize(("model", "onnx_keys", "key"), [
    ('name = "mynet"\n', None, "model: give path"),
    ('kind = "onnx"\nname = "mynet"\n', None, "model.name"),
    ('kind = "plugin"\nname = "mynet"\n', None, "model.path"),
    ("", "", "model.onnx.class_names"),
    ("", 'class_names = ["a", "b"]\nlayout = "chw"\n', "model.onnx"),
])
def test_a_model_key_that_does_not_apply_is_refused_naming_it(tmp_path, model, onnx_keys, key):
    export(tmp_path / "unet.onnx")
    with pytest.raises(SystemFileError, match=key.replace(".", r"\.")) as err:
        load_system(system_file(tmp_path, model=model, onnx_keys=onnx_keys))
    assert "\n" not in str(err.value) and "uav-el.toml" in str(err.value)


@pytest.mark.parametrize(("text", "key"), [
    ('[model]\nkind = "builtin"\nunreachable = ["water"]\n', "model.unreachable"),
    ('[model]\nkind = "builtin"\nclasses = ["a", "b"]\n', "model.classes"),
])
def test_builtin_keys_that_cannot_apply_are_refused(tmp_path, text, key):
    path = tmp_path / "uav-el.toml"
    path.write_text('format = "uav-el-system/1"\n' + text)
    with pytest.raises(SystemFileError, match=key.replace(".", r"\.")) as err:
        load_system(path)
    assert "\n" not in str(err.value)


# -- external data ----------------------------------------------------------------------------------
def test_external_data_loads_and_is_hashed_into_the_identity(tmp_path, monkeypatch):
    inline = load_onnx_model(export(tmp_path / "inline.onnx"), contract={"class_names": CLASSES})
    folder = tmp_path / "ext"
    folder.mkdir()
    path = export(folder / "unet.onnx", external=True)
    found = read_onnx(path)
    assert found.external == {"weights.bin": sha256_file(folder / "weights.bin")}
    listing = (f"uav-el-onnx-external/1\nonnx {sha256_file(path)}\n"
               f"data {sha256_file(folder / 'weights.bin')} weights.bin\n")
    assert found.sha256 == hashlib.sha256(listing.encode()).hexdigest() == file_identity(path)
    assert found.sha256 == external_identity(sha256_file(path), found.external) != sha256_file(path)
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    (elsewhere / "weights.bin").write_bytes(b"\0" * (folder / "weights.bin").stat().st_size)
    monkeypatch.chdir(elsewhere)  # the working directory plays no part
    model = load_onnx_model(path, contract={"class_names": CLASSES}, sha256=found.sha256)
    np.testing.assert_array_equal(model.predict_patch(FRAME[:40, :60]), inline.predict_patch(FRAME[:40, :60]))
    seg = system_of(system_file(folder, pin=found.sha256)).segmenter()
    assert seg.weights_sha256 == found.sha256
    from assurance.campaign.model_files import model_files

    recorded = model_files({"path": str(path)}, [], DRONE)
    assert recorded[str((folder / "weights.bin").resolve())] == sha256_file(folder / "weights.bin")


def test_weights_changed_after_pinning_are_refused(tmp_path):
    path = export(tmp_path / "unet.onnx", external=True)
    pin, before = read_onnx(path).sha256, sha256_file(path)
    system = system_file(tmp_path, pin=pin)
    load_system(system)
    weights = tmp_path / "weights.bin"
    data = bytearray(weights.read_bytes())
    data[10] ^= 0xFF
    weights.write_bytes(bytes(data))
    assert sha256_file(path) == before and read_onnx(path).sha256 != pin  # only its external data changed
    with pytest.raises(SystemFileError, match="model.sha256") as err:
        load_system(system)
    assert "\n" not in str(err.value)
    with pytest.raises(WeightsError, match="SHA-256 mismatch"):
        load_onnx_model(path, contract={"class_names": CLASSES}, sha256=pin)


def relocate(path: Path, location: str) -> Path:
    """The model with every external tensor's location replaced."""
    proto = onnx.load(str(path), load_external_data=False)
    for tensor in proto.graph.initializer:
        for entry in tensor.external_data:
            if entry.key == "location":
                entry.value = location
    path.write_bytes(proto.SerializeToString())
    return path


@pytest.mark.parametrize("where", ["parent", "absolute", "symlink", "missing"])
def test_a_location_outside_the_model_folder_is_refused(tmp_path, where):
    folder = tmp_path / "model"
    folder.mkdir()
    path = export(folder / "unet.onnx", external=True)
    secret = tmp_path / "signing.key"
    secret.write_bytes((folder / "weights.bin").read_bytes())  # bytes that would load as weights
    location = {"parent": "../signing.key", "absolute": str(secret), "symlink": "link.bin",
                "missing": "nothing.bin"}[where]
    if where == "symlink":
        os.symlink(secret, folder / "link.bin")
    relocate(path, location)
    with pytest.raises(WeightsError, match="external data location") as err:
        load_onnx_model(path, contract={"class_names": CLASSES})
    text = str(err.value)
    assert "\n" not in text and str(path) in text and repr(location) in text
    with pytest.raises(SystemFileError, match="model.path") as err:  # a pinned system file: refused at load
        load_system(system_file(folder, pin="0" * 64))
    assert repr(location) in str(err.value)


# -- [model] classes and working_width for a plugin ------------------------------------------------
class SixChannels:
    """A plugin's model that does not say its classes: 6 constant channels, working at 1024 px."""

    weights_sha256 = "cd" * 32

    def working_size(self, width, height):
        return 1024, round(1024 * height / width)

    def predict_frame(self, rgb):
        w, h = self.working_size(rgb.shape[1], rgb.shape[0])
        return np.full((6, h, w), 1 / 6, np.float32)

    def predict_patch(self, rgb_patch):
        return np.full((6, *rgb_patch.shape[:2]), 1 / 6, np.float32)


def plugin_source(**extra):
    return {"kind": "plugin", "name": "six", "path": None, "sha256": None, "onnx": None, "class_map": TO_DRONE,
            "unreachable": UNREACHABLE, "labels": DRONE.to_dict(), "system": "uav-el.toml", **extra}


def test_a_plugin_gets_its_channel_names_from_classes(monkeypatch):
    import pickle

    import el.segmentation.factory as factory
    from assurance.system.model import build_model

    monkeypatch.setattr(factory, "load_model", lambda *a, **k: SixChannels())
    model = build_model(plugin_source(classes=CLASSES))
    assert labels_of(model) == DRONE and model.weights_sha256 == "cd" * 32
    probs = model.predict_patch(FRAME[:20, :30])
    assert probs.shape == (DRONE.num_classes, 20, 30) and probs[DRONE.ids["roof"]].max() == np.float32(1 / 6)
    assert labels_of(pickle.loads(pickle.dumps(model))) == DRONE
    with pytest.raises(WeightsError, match="class map") as err:  # without classes: UAVid is assumed, and refused
        build_model(plugin_source())
    assert "uav-el.toml" in str(err.value)
    with pytest.raises(WeightsError, match="model.working_width: the model 'six' works at 1024 px") as err:
        build_model(plugin_source(classes=CLASSES, working_width=512))
    assert "\n" not in str(err.value)
