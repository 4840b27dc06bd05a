"""The campaign's signed statement: a run is signed over its task list and files; anything changed after is named."""

from __future__ import annotations

import json
import shutil

import pytest

from assurance.attest.keys import create_key
from assurance.campaign.attestation import ATTESTATION, check_run_attestation, sign_run


@pytest.fixture
def signed(tiny_campaign, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(tiny_campaign["run"], run)
    key = create_key(tmp_path / "key.pem")
    sign_run(run, key)
    return run, key, {key.keyid: key.public}


def test_a_signed_run_verifies(signed):
    run, key, trusted = signed
    got = check_run_attestation(run, trusted)
    assert got.ok, got.problems
    assert got.keyid == key.keyid and got.predicate["missing"] == []
    assert len(got.predicate["tasks"]) == json.loads((run / "manifest.json").read_text())["tasks"]


def test_signing_is_deterministic(signed):
    run, key, _ = signed
    first = (run / ATTESTATION).read_bytes()
    sign_run(run, key)
    assert (run / ATTESTATION).read_bytes() == first


def test_a_shard_copied_in_after_signing_is_named(signed):
    run, _, trusted = signed
    shards = sorted((run / "shards").iterdir())
    shutil.copytree(shards[0], run / "shards" / "none-s3__seq99_000001")
    problems = check_run_attestation(run, trusted).problems
    assert any("seq99_000001/images.parquet: not in the signed statement" in p for p in problems)


def test_an_edited_shard_resealed_in_its_own_sums_is_named(signed):
    from helpers import reseal_shard

    run, _, trusted = signed
    name = sorted((run / "shards").iterdir())[0].name
    f = run / "shards" / name / "images.parquet"
    f.write_bytes(f.read_bytes() + b"\0")
    reseal_shard(run, name)
    problems = check_run_attestation(run, trusted).problems
    assert any(f"{name}/images.parquet: altered after signing" in p for p in problems)


def test_a_removed_shard_and_an_edited_manifest_are_named(signed):
    run, _, trusted = signed
    name = sorted((run / "shards").iterdir())[-1].name
    shutil.rmtree(run / "shards" / name)
    man = json.loads((run / "manifest.json").read_text())
    man["data"]["images"] = 420
    (run / "manifest.json").write_text(json.dumps(man))
    problems = check_run_attestation(run, trusted).problems
    assert any(f"{name}/images.parquet: missing (it was signed)" in p for p in problems)
    assert any("manifest.json: altered after signing" in p for p in problems)


def test_an_unsigned_run_or_another_key_is_refused(signed, tmp_path):
    run, _, _ = signed
    other = create_key(tmp_path / "other.pem")
    assert "none of them a trusted key" in check_run_attestation(run, {other.keyid: other.public}).problems[0]
    (run / ATTESTATION).unlink()
    assert "no signed attestation" in check_run_attestation(run, {other.keyid: other.public}).problems[0]
