"""Issue 57's fault-table rows (T70..T78, ``assurance/fault_injection/name_cases.py``) replayed through the command
line: look-alike names refused with one line (exit 2), a safe class of the category unknown and a safe class in a
well-known forbidden class's colour named on page 1, which states the gate's own verdict and shows the class's strip;
UAVid's clutter listed as the deviation the basis itself accepts; two classes of one colour refused."""

from __future__ import annotations

import json

import pytest

from assurance.cli import main
from assurance.fault_injection import table as fi
from assurance.fault_injection.name_cases import NAME_CASES

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    return fi.build_workspace(tmp_path_factory.mktemp("name-faults"), main=main)


@pytest.mark.parametrize("case", NAME_CASES, ids=lambda c: c.id)
def test_name_cases_behave(workspace, case):
    assert case.id in {c.id for c in fi.CASES}  # registered where the table is assembled: make faults replays it
    row = fi.run_case(case, workspace, main=main)
    assert row["result"] == "pass", row
    if case.expected == 2:
        assert "\n" not in row["outcome"] and "label set" in row["outcome"]


def test_the_meadow_report_says_it_on_page_one_with_the_gates_own_verdict(workspace):
    case = next(c for c in NAME_CASES if c.id.startswith("T75"))
    fi.run_case(case, workspace, main=main)
    doc = json.loads((workspace / "rep-meadow" / "evidence.json").read_text("utf-8"))
    assert doc["gate"]["result"] == "FAILED"
    found = {d["name"]: d for d in doc["basis"]["deviations"]}
    assert found["colour:meadow"]["value"] == "128,64,128" and not found["colour:meadow"]["accepted"]
    assert found["class:clutter"]["accepted"] is False  # an edited copy of UAVid: not the set the basis accepts
