"""Issue 57: a hard link has no target to resolve, so confinement by real path cannot see that a template
folder's ``notes.txt`` is the auditor's signing key under a second name. The bounded reader refuses a file with
more than one link wherever its content can reach the report as text, and refuses the auditor's key (same device
and inode) everywhere; hashed and decoded bytes (weights, ONNX files, hashed data) may stay hard links."""

from __future__ import annotations

import os
import tarfile
from pathlib import Path

import pytest

from assurance import cli
from assurance.attest.key_paths import default_key_path
from el.base import userfiles
from el.base.hashing import sha256_file


def _link(src: Path, dst: Path) -> Path:
    try:
        os.link(src, dst)
    except OSError as exc:  # pragma: no cover - a file system without hard links
        pytest.skip(f"no hard links here: {exc}")
    return dst


def test_a_text_file_with_two_links_is_refused_naming_it(tmp_path):
    (tmp_path / "a.txt").write_text("hello", "utf-8")
    link = _link(tmp_path / "a.txt", tmp_path / "b.txt")
    for read in (userfiles.read_text, userfiles.read_bytes):
        with pytest.raises(userfiles.UserFileError) as exc:
            read(link, what="report template", max_bytes=100, within=tmp_path)
        msg = str(exc.value)
        assert msg.startswith(f"{link}: a file with 2 links (a hard link)") and "\n" not in msg
    with pytest.raises(userfiles.UserFileError, match="2 links"):
        userfiles.read_json(link, what="scene meta file", max_bytes=100)
    # hashed or decoded bytes: admitted
    assert userfiles.read_bytes(link, what="weights file", max_bytes=100, hard_links=True) == b"hello"
    assert sha256_file(link) == sha256_file(tmp_path / "a.txt")
    (tmp_path / "a.txt").unlink()  # one link again: read as any file
    assert userfiles.read_text(link, what="report template", max_bytes=100) == "hello"


def test_the_protected_key_is_refused_under_any_name_even_where_links_are_admitted(tmp_path):
    key = tmp_path / "home" / "signing-key.pem"
    key.parent.mkdir()
    key.write_text("-----BEGIN PRIVATE KEY-----\nSECRET\n-----END PRIVATE KEY-----\n", "utf-8")
    userfiles.protect(key)
    other = tmp_path / "data"
    other.mkdir()
    link = _link(key, other / "weights.bin")
    for call in (lambda: userfiles.read_bytes(link, what="weights file", max_bytes=1 << 10, hard_links=True),
                 lambda: userfiles.sha256(link, what="model file"),
                 lambda: userfiles.read_text(key, what="label set file", max_bytes=1 << 10),
                 lambda: userfiles.read_bytes(other / ".." / "home" / "signing-key.pem", what="x", max_bytes=99)):
        with pytest.raises(userfiles.UserFileError) as exc:
            call()
        assert "the auditor's signing key" in str(exc.value) and "SECRET" not in str(exc.value)
    # the auditor reading their own key
    assert b"SECRET" in userfiles.read_bytes(key, what="signing key", max_bytes=1 << 10, hard_links=True, own=True)


def test_a_removed_key_protects_no_file_that_reuses_its_inode(tmp_path):
    key = tmp_path / "k.pem"
    key.write_text("k", "utf-8")
    userfiles.protect(key)
    moved = tmp_path / "elsewhere.txt"
    key.rename(moved)  # same inode, but no longer the key: the protected path is gone
    assert userfiles.read_text(moved, what="template", max_bytes=10) == "k"


def _evidence(monkeypatch, *args):
    monkeypatch.setitem(cli.COMMANDS, "evidence", "evidence")
    return cli.main(["evidence", *map(str, args)])


@pytest.mark.parametrize("how", ["os.link", "tarfile"])
def test_a_template_folder_linking_the_auditors_key_never_prints_it(how, tiny_campaign, tmp_path, monkeypatch,
                                                                    capsys):
    """The trial's critical case, end to end: the signing key of this session (the default key file, which the
    campaign created) hard-linked into a template folder as notes.txt, included by a section."""
    key = default_key_path()
    assert key.is_file()
    secret = key.read_text("ascii").splitlines()[1]
    folder = tmp_path / "tpl"
    if how == "os.link":
        folder.mkdir()
        _link(key, folder / "notes.txt")
    else:  # Python 3.11's tarfile.extractall (default filter) makes a hard link from an absolute link name
        tar = tmp_path / "applicant.tar"
        with tarfile.open(tar, "w") as t:
            info = tarfile.TarInfo("tpl/notes.txt")
            info.type, info.linkname, info.mode = tarfile.LNKTYPE, str(key), 0o600  # 0644 would chmod the key
            t.addfile(info)
        with tarfile.open(tar) as t:
            try:
                t.extractall(tmp_path, filter="fully_trusted")
            except (OSError, tarfile.TarError) as exc:  # pragma: no cover
                pytest.skip(f"tarfile made no hard link here: {exc}")
    (folder / "auditor_issre.html.j2").write_text(
        '<section id="issre"><pre>{% include "notes.txt" %}</pre></section>\n', "utf-8")
    out = tmp_path / "r"
    try:
        code = _evidence(monkeypatch, "--run", tiny_campaign["run"], "--out", out, "--no-pdf", "--boot", 20,
                         "--templates", folder)
    finally:
        (folder / "notes.txt").unlink()  # the session's key has one link again for the tests after this one
    err = capsys.readouterr().err
    assert code == 2, err
    assert "notes.txt" in err and ("hard link" in err or "signing key" in err) and secret not in err
    left = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert left == [], left  # nothing in --out: no report, no results.csv, no argument


def test_a_flight_log_may_be_a_hard_link_but_never_the_key(tmp_path):
    log = tmp_path / "flight.jsonl"
    log.write_text('{"a": 1}\n', "utf-8")
    archived = _link(log, tmp_path / "archive.jsonl")  # rsync --link-dest backups link logs
    with userfiles.open_binary(archived, what="flight log", hard_links=True) as f:
        assert f.readline() == b'{"a": 1}\n'
    key = tmp_path / "k.pem"
    key.write_text("SECRET", "utf-8")
    userfiles.protect(key)
    with pytest.raises(userfiles.UserFileError, match="signing key"):
        userfiles.open_binary(_link(key, tmp_path / "key-log.jsonl"), what="flight log", hard_links=True)
    with pytest.raises(userfiles.UserFileError, match="not a regular file"):
        userfiles.open_binary(tmp_path, what="flight log")
