"""``uav-el verify``: the packaged requirement checks against a run through the command line, a user's own
requirement test bound and counted with them, and ``uav-el evidence`` reading what it wrote."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import hypothesis  # noqa: F401  # imported once here: the in-process pytest session would re-import it
import pytest

from assurance import cli
from assurance import requirements as rq
from assurance.campaign.integrity import verify_run

USER_TEST = """
import pytest

@pytest.mark.requirements("EL-R13")
def test_users_own_timing_check(campaign_run):
    assert (campaign_run / "manifest.json").is_file()
"""


@pytest.fixture(scope="module")
def verified(tiny_campaign, tmp_path_factory):
    """``uav-el verify`` on the tiny run with a user's own test in a folder of its own: (exit code, out)."""
    root = tmp_path_factory.mktemp("verify")
    (root / "mine").mkdir()
    (root / "mine" / "test_mine.py").write_text(USER_TEST)
    out = root / "out"
    code = cli.main(["verify", str(tiny_campaign["run"]), "--out", str(out), "--tests", str(root / "mine"),
                     "-k", "not rerun"])
    return code, out


def test_verify_writes_bound_results_and_junit(verified, tiny_campaign):
    code, out = verified
    doc = json.loads((out / "requirements.json").read_text())
    assert doc["context"]["run_digest"] == verify_run(tiny_campaign["run"]).digest
    assert doc["context"]["code"]["version"]
    assert code == (1 if doc["summary"]["failed"] else 0)
    assert doc["requirements"]["EL-R12"]["state"] == rq.VERIFIED
    r13 = [t["nodeid"] for t in doc["requirements"]["EL-R13"]["tests"]]
    assert any(n.endswith("test_mine.py::test_users_own_timing_check") for n in r13) and len(r13) == 2
    props = [p.get("value") for p in ET.parse(out / "junit.xml").iter("property") if p.get("name") == "requirements"]
    assert "EL-R13" in props


def test_evidence_reads_what_verify_wrote(verified, tiny_campaign, capsys):
    code, out = verified
    capsys.readouterr()
    cli.main(["evidence", "--run", str(tiny_campaign["run"]), "--out", str(out), "--no-pdf", "--boot", "50"])
    printed = capsys.readouterr()
    assert "gate problem" not in printed.out, printed.out
    matrix = (out / "traceability.csv").read_text()
    assert "test_users_own_timing_check" in matrix


def test_verify_refuses_what_is_not_a_run(tmp_path, capsys):
    assert cli.main(["verify", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "not a campaign run" in capsys.readouterr().err
