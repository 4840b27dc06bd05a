"""The auditor's sections of the evidence report: hazard log, safety argument, ISSRE figures, data and model records
and the AMLAS index, in the HTML, in evidence.json and as files beside the report."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from assurance.evidence import generate
from assurance.evidence.argument import check_structure, from_yaml


@pytest.fixture(scope="module")
def auditor_report(tiny_campaign, tmp_path_factory):
    out = tmp_path_factory.mktemp("auditor_report")
    generate(tiny_campaign["run"], out, pdf=False, n_boot=100)
    return out


def test_report_shows_hazards_argument_and_issre(auditor_report):
    html = (auditor_report / "evidence.html").read_text("utf-8")
    for anchor in ('id="hazards"', 'id="argument"', 'id="issre"'):
        assert anchor in html
    assert html.count('<div class="gsn-view"') == 4  # inline SVG: top page + one per strategy
    assert "data:image/svg+xml" not in html and 'href="#req-EL-R01"' in html  # its elements link
    doc = json.loads((auditor_report / "evidence.json").read_text("utf-8"))
    assert [h["id"] for h in doc["hazards"]["hazards"]][:2] == ["H1", "H2"]
    assert doc["argument"]["problems"] == []
    # no requirement results given: every requirement goal is undeveloped
    assert doc["argument"]["elements"]["G-EL-R01"]["undeveloped"] is True


def test_the_written_argument_round_trips_and_is_sound(auditor_report):
    nodes = from_yaml((auditor_report / "argument.gsn.yaml").read_text("utf-8"))
    assert check_structure(nodes) == []
    doc = json.loads((auditor_report / "evidence.json").read_text("utf-8"))
    assert set(nodes) == set(doc["argument"]["elements"])
    sums = (auditor_report / "SHA256SUMS").read_text("utf-8")
    assert "  argument.gsn.yaml\n" in sums and "  issre.csv\n" in sums


def test_issre_csv_matches_evidence_json(auditor_report):
    table = pd.read_csv(auditor_report / "issre.csv")
    doc = json.loads((auditor_report / "evidence.json").read_text("utf-8"))
    assert len(table) == len(doc["issre"]["rows"]) > 0
    assert (table["tp"] + table["fp"] + table["tn"] + table["fn"] == table["n"]).all()


def test_data_record_model_log_and_amlas_index(auditor_report):
    import jsonschema

    from assurance.evidence.render import ROOT

    doc = json.loads((auditor_report / "evidence.json").read_text("utf-8"))
    schema = json.loads((ROOT / "assurance" / "data" / "evidence.schema.json").read_text("utf-8"))
    jsonschema.validate(doc, schema)
    roles = [d["role"] for d in doc["data_record"]["datasets"]]
    assert roles[0] == "verification (this campaign)" and "monitor calibration (threshold)" in roles
    assert "learned monitor training" not in roles  # the run used lhd and lhd+ch: the learned monitor is not its
    assert {c["result"] for c in doc["data_record"]["disjoint"]} <= {"pass", "fail", "not checked"}
    items = {r["item"]: r["value"] for r in doc["model_log"]["network"]}
    assert "tiny.pt" in items["Network"] and "Test split used for" in items
    letters = {(a["stage"], a["letter"]) for a in doc["amlas"]}
    assert {(1, "A"), (2, "H"), (3, "P"), (4, "V"), (5, "Z"), (6, "EE")} <= letters  # no development set: none used
    html = (auditor_report / "evidence.html").read_text("utf-8")
    for anchor in ('id="data-record"', 'id="model-log"', 'id="amlas"'):
        assert anchor in html


def test_disjointness_is_checked_on_the_files(tmp_path):
    import shutil

    from assurance.evidence.records import disjointness

    def sample(root, name, content):
        (root / "seq00" / "Images").mkdir(parents=True, exist_ok=True)
        (root / "seq00" / "Images" / name).write_bytes(content)

    test, dev = tmp_path / "test", tmp_path / "dev"
    sample(test, "a.png", b"one")
    sample(dev, "b.png", b"two")
    rows = [{"name": "dev", "path": str(dev), "sha256": "x"}]
    checks = {c["check"]: c["result"] for c in disjointness([{"seed": 2_000_001}], "y", test, rows)}
    assert set(checks.values()) == {"pass"}
    shutil.copy(test / "seq00" / "Images" / "a.png", dev / "seq00" / "Images" / "c.png")
    checks = disjointness([{"seed": 5}], "x", test, rows)  # a train seed, the same hash, a shared image
    assert [c["result"] for c in checks] == ["fail", "fail", "fail"]


def test_model_log_of_the_shipped_network_from_its_card():
    from assurance.evidence.model_log import model_log
    from assurance.evidence.render import ROOT

    weights = ROOT / "el" / "segmentation" / "weights" / "model.pt"
    deployed = {"monitors": ["learned:walk=score,threshold=0.8"]}  # the run used the shipped learned monitor
    log = model_log({"weights": {"path": str(weights)}, "data": {"sha256": "f" * 64}, "config": deployed})
    items = {r["item"]: r["value"] for r in log["network"]}
    assert items["Test split used for"].startswith("none")
    assert "data/train" in items["Data"] and "step" in items["Selection rule"]
    assert len(log["history"]) >= 1 and {r["item"] for r in log["monitors"]} >= {"Learned monitor"}
    unused = model_log({"weights": {"path": str(weights)}, "data": {"sha256": "f" * 64},
                        "config": {"monitors": ["lhd"]}})
    assert "Learned monitor" not in {r["item"] for r in unused["monitors"]}  # only the monitors the run used
    card = json.loads((weights.with_suffix(".json")).read_text("utf-8"))
    used = card["training"]["data"]["train"]["sha256"]
    log = model_log({"weights": {"path": str(weights)}, "data": {"sha256": used}})
    assert {r["item"]: r["value"] for r in log["network"]}["Test split used for"].startswith("THE RUN'S TEST DATA")
