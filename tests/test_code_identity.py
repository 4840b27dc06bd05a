"""The code's identity: a git commit only from the toolkit's own checkout, never an enclosing repository's; the
package files' hash otherwise; EL-R12 accepts either."""

from __future__ import annotations

import subprocess

import pytest

from assurance import code_identity as ci
from assurance import requirements as rq

PYPROJECT = '[project]\nname = "{name}"\nversion = "0.1.0"\n'


def _git_repo(path, name="other-project"):
    path.mkdir(parents=True, exist_ok=True)
    (path / "pyproject.toml").write_text(PYPROJECT.format(name=name))
    for args in (["init", "-q"], ["add", "pyproject.toml"],
                 ["-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "x"]):
        subprocess.run(["git", "-C", str(path), *args], check=True, capture_output=True)
    return path


@pytest.mark.skipif(not (ci.install_root() / ".git").exists(), reason="the toolkit is not run from a git checkout "
                    "here (an installed wheel, an unpacked sdist)")
def test_this_checkout_is_the_toolkits_own():
    assert ci.own_checkout() == ci.install_root()
    ident = ci.code_identity()
    assert ident["source"] == "checkout" and ident["git_commit"] and len(ident["sha256"]) == 64
    assert ident["files"] > 100 and ident["version"]


def test_an_install_inside_another_repository_has_no_commit(tmp_path, monkeypatch):
    repo = _git_repo(tmp_path / "users-repo")
    site = repo / ".venv" / "lib" / "site-packages"
    site.mkdir(parents=True)
    monkeypatch.setattr(ci, "install_root", lambda: site)
    assert ci.own_checkout() is None and ci.git_commit() is None
    monkeypatch.setattr(ci, "install_root", lambda: repo)  # a repository of another project at the top
    assert ci.own_checkout() is None and ci.git_commit() is None


def test_only_the_top_of_a_checkout_named_uav_el_assurance_counts(tmp_path, monkeypatch):
    own = _git_repo(tmp_path / "own", name=ci.PROJECT)
    monkeypatch.setattr(ci, "install_root", lambda: own)
    assert ci.own_checkout() == own and len(ci.git_commit()) == 40
    nested = own / "sub"
    nested.mkdir()
    (nested / "pyproject.toml").write_text(PYPROJECT.format(name=ci.PROJECT))
    (nested / ".git").write_text("gitdir: nowhere\n")
    monkeypatch.setattr(ci, "install_root", lambda: nested)
    assert ci.own_checkout() is None


def test_the_hash_covers_the_package_files(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "m.py").write_text("x = 1\n")
    (tmp_path / "a" / "w.pt").write_bytes(b"weights")
    before = ci.tree_sha256([tmp_path / "a"], base=tmp_path)
    (tmp_path / "a" / "w.pt").write_bytes(b"other weights")  # weights are identified by their own hash
    assert ci.tree_sha256([tmp_path / "a"], base=tmp_path) == before
    (tmp_path / "a" / "m.py").write_text("x = 2\n")
    assert ci.tree_sha256([tmp_path / "a"], base=tmp_path) != before and before[1] == 1


@pytest.mark.requirements("EL-R12")
@pytest.mark.parametrize("code, ok", [
    ({"version": "0.1.0", "git_commit": "ab" * 20}, True),
    ({"version": "0.1.0", "git_commit": None, "sha256": "c" * 64, "source": "installed"}, True),
    ({"version": "0.1.0", "git_commit": None, "sha256": None}, False),
    ({"version": None, "git_commit": None, "sha256": "c" * 64}, False),
])
def test_el_r12_identifies_code_by_commit_or_by_version_and_file_hash(code, ok):
    man = {"weights": {"sha256": "a" * 64}, "data": {"sha256": "b" * 64}, "config": {"x": 1}, "code": code}
    ev = rq.check_artefacts_identified(man)
    assert (ev.status == rq.PASS) is ok, ev.summary
