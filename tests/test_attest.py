"""Signed attestations: DSSE envelopes, keys kept outside the run, in-toto statements and their subjects."""

from __future__ import annotations

import base64
import json
import stat

import pytest

from assurance.attest import AttestationError
from assurance.attest.dsse import pae, read_envelope, sign_envelope, verify_envelope, write_envelope
from assurance.attest.keys import (
    KEY_ENV,
    create_key,
    default_key_path,
    load_signing_key,
    load_trusted_keys,
    public_pem,
)
from assurance.attest.statement import make_statement, open_statement, sign_statement, subject_problems


@pytest.fixture
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.delenv(KEY_ENV, raising=False)
    monkeypatch.delenv("UAV_EL_TRUSTED_KEYS", raising=False)
    return tmp_path


def test_pae_is_the_dsse_v1_encoding():
    assert pae("http://example.com/HelloWorld", b"hello world") == \
        b"DSSEv1 29 http://example.com/HelloWorld 11 hello world"


def test_a_key_is_created_on_first_use_private_and_reused(home):
    first = load_signing_key()
    path = default_key_path()
    assert path.is_file() and stat.S_IMODE(path.stat().st_mode) == 0o600
    again = load_signing_key()
    assert again.keyid == first.keyid and len(first.keyid) == 64


def test_without_create_a_missing_key_is_an_error(home):
    with pytest.raises(AttestationError, match="no signing key"):
        load_signing_key(create=False)


def test_the_key_may_come_from_the_environment_as_pem_text(home, monkeypatch):
    made = create_key(home / "ci.pem")
    monkeypatch.setenv(KEY_ENV, (home / "ci.pem").read_text())
    assert load_signing_key().keyid == made.keyid
    monkeypatch.setenv(KEY_ENV, str(home / "ci.pem"))
    assert load_signing_key().keyid == made.keyid


def test_a_key_inside_the_run_it_signs_is_refused(home):
    run = home / "run"
    create_key(run / "key.pem")
    with pytest.raises(AttestationError, match="inside"):
        load_signing_key(run / "key.pem", outside=run)


def test_envelope_round_trip_and_tampering(home):
    key = load_signing_key()
    env = sign_envelope(b'{"a": 1}', key.key, key.keyid)
    trusted = {key.keyid: key.public}
    assert verify_envelope(env, trusted) == (b'{"a": 1}', key.keyid)
    forged = dict(env, payload=base64.b64encode(b'{"a": 2}').decode())
    with pytest.raises(AttestationError, match="altered after signing"):
        verify_envelope(forged, trusted)
    with pytest.raises(AttestationError, match="payloadType"):
        verify_envelope(dict(env, payloadType="text/plain"), trusted)
    with pytest.raises(AttestationError, match="no signature"):
        verify_envelope(dict(env, signatures=[]), trusted)


def test_a_signature_by_an_untrusted_key_is_refused(home):
    mine, theirs = load_signing_key(), create_key(home / "other.pem")
    env = sign_envelope(b"x", theirs.key, theirs.keyid)
    with pytest.raises(AttestationError, match="none of them a trusted key"):
        verify_envelope(env, {mine.keyid: mine.public})
    # a forger who relabels their signature with the trusted keyid still fails the check
    relabelled = dict(env, signatures=[{"keyid": mine.keyid, "sig": env["signatures"][0]["sig"]}])
    with pytest.raises(AttestationError, match="altered"):
        verify_envelope(relabelled, {mine.keyid: mine.public})


def test_trusted_keys_from_a_file_a_folder_or_the_local_key(home):
    a, b = create_key(home / "a.pem"), create_key(home / "b.pem")
    keys = home / "keys"
    keys.mkdir()
    (keys / "a.pub").write_text(public_pem(a.public))
    (keys / "both.pem").write_text(public_pem(a.public) + public_pem(b.public))
    assert set(load_trusted_keys(keys)) == {a.keyid, b.keyid}
    assert set(load_trusted_keys(keys / "a.pub")) == {a.keyid}
    local = load_signing_key()
    assert set(load_trusted_keys()) == {local.keyid}
    (home / "junk.pem").write_text("not a key")
    with pytest.raises(AttestationError, match="no PEM public key"):
        load_trusted_keys(home / "junk.pem")


def test_statement_signed_opened_and_its_subjects_compared(home, tmp_path):
    key = load_signing_key()
    stmt = make_statement({"a.txt": "11" * 32, "b.txt": "22" * 32}, "campaign", {"tasks": 2})
    write_envelope(tmp_path / "s.dsse.json", sign_statement(stmt, key))
    opened, keyid = open_statement(read_envelope(tmp_path / "s.dsse.json"), {key.keyid: key.public}, "campaign",
                                   where="s.dsse.json")
    assert opened == json.loads(json.dumps(stmt)) and keyid == key.keyid
    with pytest.raises(AttestationError, match="predicate"):
        open_statement(read_envelope(tmp_path / "s.dsse.json"), {key.keyid: key.public}, "requirements", where="s")
    now = {"a.txt": "11" * 32, "b.txt": "33" * 32, "c.txt": "44" * 32}
    problems = subject_problems(opened, now)
    assert any("c.txt: not in the signed statement" in p for p in problems)
    assert any("b.txt: altered after signing" in p for p in problems)
    assert subject_problems(opened, {"a.txt": "11" * 32}) == ["b.txt: missing (it was signed)"]


def test_a_missing_or_garbled_envelope_names_the_file(tmp_path):
    with pytest.raises(AttestationError, match="missing"):
        read_envelope(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(AttestationError, match="bad.json: not a JSON envelope"):
        read_envelope(tmp_path / "bad.json")
