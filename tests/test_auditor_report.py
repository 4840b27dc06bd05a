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
    assert html.count("data:image/svg+xml;base64,") == 4  # top page + one per strategy
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


def test_issre_csv_matches_evidence_json(auditor_report):
    table = pd.read_csv(auditor_report / "issre.csv")
    doc = json.loads((auditor_report / "evidence.json").read_text("utf-8"))
    assert len(table) == len(doc["issre"]["rows"]) > 0
    assert (table["tp"] + table["fp"] + table["tn"] + table["fn"] == table["n"]).all()
