"""The requirement results' signed statement: bound to the files and to what they were judged on."""

from __future__ import annotations

from assurance.attest.keys import create_key
from assurance.requirements.attestation import check_results_attestation, sign_results

PINS = {"run_digest": "ab" * 32, "registry_sha256": "cd" * 32, "waivers_sha256": "ef" * 32, "tests_run": 17}


def _signed(tmp_path):
    res, junit = tmp_path / "requirements.json", tmp_path / "junit.xml"
    res.write_text('{"requirements": {}}')
    junit.write_text("<testsuites/>")
    key = create_key(tmp_path / "k.pem")
    sign_results(res, key, PINS, junit=junit)
    return res, junit, key, {key.keyid: key.public}


def test_signed_results_verify_and_pin_what_they_were_judged_on(tmp_path):
    res, junit, key, trusted = _signed(tmp_path)
    pred, problems = check_results_attestation(res, trusted, PINS, junit=junit)
    assert problems == [] and pred["tests_run"] == 17 and pred["signed_by"] == key.keyid


def test_results_edited_after_signing_or_judged_on_a_weaker_registry_are_named(tmp_path):
    res, junit, _, trusted = _signed(tmp_path)
    res.write_text('{"requirements": {"EL-R10": {"state": "verified"}}}')
    _, problems = check_results_attestation(res, trusted, {**PINS, "registry_sha256": "00" * 32}, junit=junit)
    assert any("requirements.json: altered after signing" in p for p in problems)
    assert any("signed with registry_sha256" in p for p in problems)


def test_results_written_by_hand_are_not_evidence(tmp_path):
    res = tmp_path / "requirements.json"
    res.write_text("{}")
    _, problems = check_results_attestation(res, {}, PINS)
    assert len(problems) == 1 and "only as `uav-el verify` wrote and signed them" in problems[0]
