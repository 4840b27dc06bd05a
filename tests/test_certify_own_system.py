"""The second example of docs/certify.md ("Certify your own system") end to end on tiny data: a network not
trained here (the shipped one exported to ONNX stands in for it), data in another palette with per-frame poses,
the user's own camera and targets, all declared in examples/my-drone/uav-el.toml (used unchanged); the evidence
PDF names that network's hash and the system file. No edit to the package."""

import json
import shutil
from pathlib import Path

import pytest

from assurance import cli

pytest.importorskip("onnxruntime")
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "my-drone"
TO_CITY_SURVEY = {"road": "asphalt", "low_vegetation": "lawn", "building": "house", "moving_car": "driving_vehicle",
                  "human": "pedestrian", "tree": "canopy", "static_car": "parked_vehicle", "clutter": "misc"}


@pytest.fixture(scope="module")
def walkthrough(tmp_path_factory):
    root = tmp_path_factory.mktemp("walkthrough")
    example = root / "examples" / "my-drone"
    shutil.copytree(EXAMPLE, example)
    main = cli.main
    assert main(["export-onnx", "--out", str(example / "net.onnx")]) == 0
    assert main(["synth", "--out", str(root / "data" / "src"), "--scenes", "3", "--size", "320x180",
                 "--split", "test", "--sensor-width", "13.2", "--hfov", "73.7", "--heights", "40:70",
                 "--pitches", "50:80", "--no-progress"]) == 0
    assert main(["recolour", "--data", str(root / "data" / "src"), "--out", str(root / "data" / "my-drone"),
                 "--to", str(example / "labels.yaml"), "--map", json.dumps(TO_CITY_SURVEY)]) == 0
    system = example / "uav-el.toml"
    run = root / "runs" / "my-drone"
    assert main(["campaign", "--system", str(system), "--out", str(run), "--perturbations", "none", "fog",
                 "--monitors", "lhd", "--quiet"]) == 0
    return {"root": root, "system": system, "run": run, "onnx": example / "net.onnx"}


def test_the_campaign_assessed_the_users_network_poses_and_palette(walkthrough):
    from el.base.hashing import sha256_file

    man = json.loads((walkthrough["run"] / "manifest.json").read_text())
    assert man["weights"]["sha256"] == sha256_file(walkthrough["onnx"])
    assert man["system"]["sha256"] == sha256_file(walkthrough["system"])
    assert man["config"]["poses"] == "required"
    assert man["config"]["core"]["safety"]["radius_m"] == 2.5
    from assurance.campaign import readouts

    images = readouts.load_table(walkthrough["run"], "images")
    assert (images["fault"] == "").all(), images["fault"].tolist()
    assert images["height_m"].nunique() == 3 and images["pose_source"].eq("frame").all()


def test_the_evidence_pdf_names_the_network_and_the_system_file(walkthrough, tmp_path):
    from el.base.hashing import sha256_file

    out = tmp_path / "report"
    code = cli.main(["evidence", "--system", str(walkthrough["system"]), "--run", str(walkthrough["run"]),
                     "--out", str(out), "--boot", "50"])
    assert code == 1  # no requirement results given: nothing is verified, and that fails the gate
    evidence = json.loads((out / "evidence.json").read_text())
    assert evidence["identity"]["weights_sha256"] == sha256_file(walkthrough["onnx"])
    assert evidence["identity"]["system_sha256"] == sha256_file(walkthrough["system"])
    assert evidence["parameters"]["confidence"] == 0.99 and evidence["parameters"]["radius_m"] == 2.5
    assert evidence["parameters"]["deployed_monitor"] == "lhd"
    html = (out / "evidence.html").read_text()
    assert "Example Drone Operations Ltd." in html and "my-drone" in html and "R = 2.5 m" in html
    assert "Declared operating domain" in html and "40 to 70 m" in html and "Perturbation fog" in html
    # nothing of the shipped system: its gate study, weights, monitor files, release command, forbidden classes
    for shipped in ("Out-of-domain frame gates, measured on validation scenes", "0d3dab88", "learned.json",
                    "frame_gate.json", "make release-evidence", "road, car", "45 degrees"):
        assert shipped not in html, shipped
    assert "house" in html and "guarded by telemetry only" in html  # its forbidden classes; it has no frame gate
    pdf = out / "evidence.pdf"
    if evidence["pdf_error"] is None:
        assert pdf.is_file() and pdf.read_bytes().startswith(b"%PDF")


def test_evidence_uses_the_runs_system_file_and_refuses_another(walkthrough, tmp_path, capsys):
    from el.base.hashing import sha256_file

    out = tmp_path / "own"
    cli.main(["evidence", "--run", str(walkthrough["run"]), "--out", str(out), "--no-pdf", "--boot", "20"])
    assert "(the run's own)" in capsys.readouterr().out  # no --system: the run's system file, found and unchanged
    doc = json.loads((out / "evidence.json").read_text())
    assert doc["identity"]["system_sha256"] == sha256_file(walkthrough["system"])
    other = tmp_path / "other.toml"
    other.write_text('[system]\nname = "another"\n')
    code = cli.main(["evidence", "--run", str(walkthrough["run"]), "--out", str(tmp_path / "r"), "--no-pdf",
                     "--boot", "20", "--system", str(other)])
    assert code == 1
    assert "another system file" in capsys.readouterr().out


def test_verify_judges_the_run_with_its_system_file_and_refuses_another(walkthrough, tmp_path, capsys):
    from el.base.hashing import sha256_file

    out = tmp_path / "verify"
    cli.main(["verify", str(walkthrough["run"]), "--out", str(out), "--system", str(walkthrough["system"]),
              "-k", "not rerun"])
    doc = json.loads((out / "requirements.json").read_text())
    assert doc["context"]["system_sha256"] == sha256_file(walkthrough["system"])
    assert doc["registry"]["targets"]["radius_m"] == 2.5  # the system file's targets judged the run
    other = tmp_path / "other.toml"
    other.write_text('[system]\nname = "another"\n')
    capsys.readouterr()
    assert cli.main(["verify", str(walkthrough["run"]), "--out", str(tmp_path / "o"), "--system", str(other)]) == 2
    assert "assessed another system file" in capsys.readouterr().err
