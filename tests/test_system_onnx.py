"""An ONNX network from elsewhere declared in a system file: its contract and classes in [model.onnx], its hash
pinned; a file whose output has the wrong class count, or another hash, is refused with one line (exit 2)
before anything is written."""

import json

import pytest

pytest.importorskip("onnxruntime")
from helpers import scene_ids  # noqa: E402
from onnx_helpers import MEAN, STD, ColourNet, Variant, export_raw, noisy_colours  # noqa: E402

from assurance import cli  # noqa: E402
from assurance.dataio.uavid import write_sample  # noqa: E402
from el.base.hashing import sha256_file  # noqa: E402
from el.classes.labels import UAVID  # noqa: E402

CLASSES = json.dumps(list(UAVID.names))


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("onnx_data")
    for i in range(2):
        ids = scene_ids(256, 144, seed=i, road_col=60 + 80 * i)
        write_sample(root, "seq00", f"{i:06d}", noisy_colours(ids, seed=i), ids, labels=UAVID)
    return root


def system_file(tmp_path, onnx_name, *, extra=""):
    text = (f'[model]\npath = "{onnx_name}"\nsha256 = "{sha256_file(tmp_path / onnx_name)}"\n'
            f"[model.onnx]\nclass_names = {CLASSES}\nchannel_order = \"bgr\"\nscaling = \"mean_std\"\n"
            f"mean = {MEAN}\nstd = {STD}\nvalue_range = 255\n{extra}[monitor]\nspec = \"lhd\"\n")
    p = tmp_path / "uav-el.toml"
    p.write_text(text)
    return p


def campaign(system, data, out):
    return cli.main(["campaign", "--system", str(system), "--data", str(data), "--out", str(out),
                     "--perturbations", "none", "--monitors", "lhd", "--quiet"])


def test_a_foreign_onnx_with_its_contract_in_the_system_file_runs_a_campaign(tmp_path, data):
    export_raw(Variant(ColourNet(), bgr=True, mean_std=True), tmp_path / "net.onnx")  # no metadata at all
    system = system_file(tmp_path, "net.onnx")
    assert campaign(system, data, tmp_path / "run") == 0
    man = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert man["weights"]["sha256"] == sha256_file(tmp_path / "net.onnx")
    from assurance.campaign import readouts

    images = readouts.load_table(tmp_path / "run", "images")
    assert (images["fault"] == "").all() and (images["candidates"] > 0).all()


def test_wrong_class_count_is_refused_before_anything(tmp_path, data, capsys):
    export_raw(Variant(ColourNet(), bgr=True, mean_std=True, drop=True), tmp_path / "seven.onnx")
    system = system_file(tmp_path, "seven.onnx")
    assert campaign(system, data, tmp_path / "run") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "seven.onnx" in err and "7" in err, err
    assert not (tmp_path / "run").exists()


def test_an_onnx_file_that_is_not_the_pinned_one_is_refused(tmp_path, data, capsys):
    export_raw(Variant(ColourNet(), bgr=True, mean_std=True), tmp_path / "net.onnx")
    system = system_file(tmp_path, "net.onnx")
    export_raw(Variant(ColourNet(), mean_std=True), tmp_path / "net.onnx")  # replaced after pinning
    assert campaign(system, data, tmp_path / "run") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "model.sha256" in err, err
    assert not (tmp_path / "run").exists()


def test_monitors_that_need_the_network_inside_are_refused_at_load(tmp_path, data, capsys):
    export_raw(Variant(ColourNet(), bgr=True, mean_std=True), tmp_path / "net.onnx")
    system = system_file(tmp_path, "net.onnx")
    code = cli.main(["campaign", "--system", str(system), "--data", str(data), "--out", str(tmp_path / "run"),
                     "--perturbations", "none", "--monitors", "lhd", "lhd+mcd:n=10,rho=0.9", "--quiet"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "mcd" in err.lower(), err
    assert not (tmp_path / "run").exists()
