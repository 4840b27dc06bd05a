"""The campaign's signed statement: a run is signed over its task list and files; anything changed after is named."""

from __future__ import annotations

import base64
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


# ------------------------------------------------------------------------------------------------
# At the command line: the evidence step refuses what was not signed by a trusted key
# ------------------------------------------------------------------------------------------------
def _evidence(run, out, *extra):
    from assurance import cli

    return cli.main(["evidence", "--run", str(run), "--out", str(out), "--no-pdf", "--boot", "50", *map(str, extra)])


def test_a_fabricated_run_is_refused_with_one_line(tiny_campaign, tmp_path, capsys):
    """One real shard copied under many new task names and the shard index deleted: exit 4, the file named."""
    run = tmp_path / "run"
    shutil.copytree(tiny_campaign["run"], run)
    first = sorted((run / "shards").iterdir())[0]
    for i in range(20):
        shutil.copytree(first, run / "shards" / f"none-s3__seq00_{900000 + i}")
    (run / "shards.json").unlink()
    assert _evidence(run, tmp_path / "rep") == 4
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not the campaign that was signed" in err[0] and "not in the signed statement" in err[0]


def test_the_evidence_names_the_signer_and_refuses_other_keys(tiny_campaign, tmp_path, capsys):
    from assurance.attest.keys import load_signing_key, public_pem

    run = tmp_path / "run"
    shutil.copytree(tiny_campaign["run"], run)
    mine = tmp_path / "mine.pem"
    mine.write_text(public_pem(load_signing_key().public))
    assert _evidence(run, tmp_path / "rep", "--trusted-keys", mine) in (0, 1)
    doc = json.loads((tmp_path / "rep" / "evidence.json").read_text())
    assert doc["identity"]["campaign_signed_by"] == load_signing_key().keyid
    assert load_signing_key().keyid in (tmp_path / "rep" / "evidence.html").read_text()
    other = create_key(tmp_path / "other.pem")
    theirs = tmp_path / "theirs.pem"
    theirs.write_text(public_pem(other.public))
    capsys.readouterr()
    assert _evidence(run, tmp_path / "rep2", "--trusted-keys", theirs) == 4
    assert "none of them a trusted key" in capsys.readouterr().err


def test_uav_el_keys_prints_the_fingerprint_and_writes_the_public_key(tmp_path, capsys):
    from assurance import cli
    from assurance.attest.keys import load_signing_key, load_trusted_keys

    assert cli.main(["keys", "--public", "--out", str(tmp_path / "pub.pem")]) == 0
    out = capsys.readouterr().out
    assert load_signing_key().keyid in out and "BEGIN PUBLIC KEY" in out
    assert set(load_trusted_keys(tmp_path / "pub.pem")) == {load_signing_key().keyid}


def test_signing_hashes_each_file_once_and_covers_the_files_as_they_are(signed, monkeypatch):
    import assurance.campaign.attestation as attestation
    import assurance.campaign.integrity as integrity
    from assurance.attest.dsse import read_envelope
    from assurance.attest.statement import subjects
    from assurance.campaign import readouts
    from assurance.campaign.integrity import verify_run
    from el.base import hashing

    run, key, _ = signed
    assert attestation.run_subjects(run, verify_run(run).sums) == attestation.run_subjects(run)
    seen: list[str] = []

    def counted(path, *args, **kwargs):
        seen.append(str(path))
        return hashing.sha256_file(path, *args, **kwargs)

    for module in (attestation, integrity, readouts):
        monkeypatch.setattr(module, "sha256_file", counted)
    sign_run(run, key)
    files = [p for p in (run / "shards").glob("*/*") if p.is_file() and p.name != readouts.SUMS]
    assert sorted(seen) == sorted([str(run / "manifest.json"), *map(str, files)])  # each once
    name = sorted((run / "shards").iterdir())[0].name
    edited = run / "shards" / name / "images.parquet"
    edited.write_bytes(edited.read_bytes() + b"\0")  # damaged (not resealed): its stale sum must not be signed
    sign_run(run, key)
    stmt = json.loads(base64.b64decode(read_envelope(run / ATTESTATION)["payload"]))
    assert subjects(stmt)[f"shards/{name}/images.parquet"] == hashing.sha256_file(edited)


def test_an_unattested_run_is_a_damaged_run_with_its_own_line():
    from assurance.campaign.attestation import UnattestedRunError
    from assurance.campaign.readouts import DamagedRunError

    err = UnattestedRunError("RUN", ["a", "b", "c", "d"])
    assert isinstance(err, DamagedRunError) and err.problems == ["a", "b", "c", "d"] and str(err.run_dir) == "RUN"
    assert str(err) == "RUN: not the campaign that was signed: a; b; c; ... 1 more"
    assert str(DamagedRunError("RUN", ["x"])) == ("RUN: damaged run, 1 shard problem(s): x (re-run the same "
                                                  "`uav-el campaign` command to re-compute the damaged shards)")
