"""One reader for every applicant file (issue 50): ``el.base.userfiles`` confines a file to its folder (``within=``: a
symbolic link out of it is refused naming the link and its target), never reads under ``/proc``, ``/sys`` or
``/dev``, hashes in chunks under a cap; scene meta, recorded model files and readout tables go through it (a FIFO
or ``/dev/zero`` there never hangs, a table is refused by its row count before it is loaded); ``python -m
assurance`` imports no module of the working folder; a system fact is literal text; an impossible waiver date
names the file and the waiver.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import within_seconds

from el.base import userfiles
from el.base.hashing import sha256_file

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo") or not Path("/proc/self").exists(),
                                reason="needs FIFOs and /proc (Linux)")


@pytest.fixture
def folder(tmp_path) -> Path:
    """``tmp/tpl`` holding ``ok.j2``, ``inner.j2`` (a link to ok.j2), ``out.j2`` (a link to ``tmp/secret.txt``)."""
    (tmp_path / "secret.txt").write_text("SECRET", encoding="utf-8")
    tpl = tmp_path / "tpl"
    tpl.mkdir()
    (tpl / "ok.j2").write_text("fine", encoding="utf-8")
    (tpl / "inner.j2").symlink_to("ok.j2")
    (tpl / "out.j2").symlink_to(tmp_path / "secret.txt")
    return tpl


# -- the reader ------------------------------------------------------------------------------------
def test_within_reads_files_of_the_folder_and_links_that_stay_in_it(folder):
    for name in ("ok.j2", "inner.j2"):
        assert userfiles.read_text(folder / name, what="report template", max_bytes=100, within=folder) == "fine"
        assert userfiles.read_bytes(folder / name, what="report template", max_bytes=100, within=folder) == b"fine"
    assert userfiles.check_path(folder / "inner.j2", what="t", within=folder) == (folder / "ok.j2").resolve()
    assert userfiles.not_regular(folder / "inner.j2", what="t", within=folder) is None
    # without within, the same call as before (backward compatible)
    assert userfiles.read_text(folder / "out.j2", what="report template", max_bytes=100) == "SECRET"


def test_a_link_out_of_the_folder_is_refused_naming_the_link_and_its_target(folder, tmp_path):
    link = folder / "out.j2"
    with pytest.raises(userfiles.UserFileError) as exc:
        userfiles.read_text(link, what="report template", max_bytes=100, within=folder)
    msg = str(exc.value)
    assert msg.startswith(f"{link}: a symbolic link to {tmp_path / 'secret.txt'}, outside its folder {folder}")
    assert "a report template must lie inside its folder" in msg and "\n" not in msg
    assert "SECRET" not in msg
    # a .. path, and a file under a linked folder, resolve outside too
    for path in (folder / ".." / "secret.txt",):
        with pytest.raises(userfiles.UserFileError, match="outside its folder"):
            userfiles.read_bytes(path, what="report template", max_bytes=100, within=folder)
    (folder / "sub").symlink_to(tmp_path, target_is_directory=True)
    with pytest.raises(userfiles.UserFileError, match=r"resolves to .*secret\.txt, outside its folder"):
        userfiles.read_bytes(folder / "sub" / "secret.txt", what="report template", max_bytes=100, within=folder)
    assert "outside its folder" in userfiles.not_regular(link, what="t", within=folder)
    with pytest.raises(userfiles.UserFileError, match="outside its folder"):
        sha256_file(link, within=folder)


@pytest.mark.parametrize("path", ["/proc/self/pagemap", "/proc/self/environ", "/proc/self/status"])
def test_kernel_files_are_refused_whatever_stat_says(path, tmp_path):
    with within_seconds(10):
        with pytest.raises(userfiles.UserFileError, match=r"under /proc: a model file must be a regular file"):
            userfiles.read_bytes(path, what="model file", max_bytes=1 << 30)
        with pytest.raises(userfiles.UserFileError, match="under /proc"):
            sha256_file(path, what="model file")
        link = tmp_path / "innocent.json"
        link.symlink_to(path)
        with pytest.raises(userfiles.UserFileError, match=f"a symbolic link to {path}, which resolves to .* /proc"):
            userfiles.read_text(link, what="scene meta file", max_bytes=1 << 20)
        assert "under /proc" in userfiles.not_regular(link, what="model file")


def test_sys_and_dev_are_refused_and_devices_keep_their_message(tmp_path):
    sys_file = next((p for p in (Path("/sys/kernel/mm/transparent_hugepage/enabled"), Path("/sys/power/state"))
                     if p.is_file()), None)
    if sys_file is not None:
        with pytest.raises(userfiles.UserFileError, match="under /sys"):
            userfiles.read_bytes(sys_file, what="label set file", max_bytes=1 << 20)
    with pytest.raises(userfiles.UserFileError, match="a character device, not a regular file"):
        userfiles.read_bytes("/dev/zero", what="label set file", max_bytes=1 << 20)
    with pytest.raises(userfiles.UserFileError, match="under /dev"):
        userfiles.check_path("/dev/shm/x", what="file")


def test_hashing_is_bounded_and_chunked(tmp_path):
    data = os.urandom(3 << 20)
    f = tmp_path / "model.onnx"
    f.write_bytes(data)
    assert sha256_file(f, chunk=1 << 16) == hashlib.sha256(data).hexdigest() == userfiles.sha256(f, what="m")
    with pytest.raises(userfiles.UserFileError, match=f"{len(data)} bytes exceeds the limit of 1000 bytes"):
        sha256_file(f, max_bytes=1000)
    with pytest.raises(FileNotFoundError):  # as open() would: callers that handle it keep working
        sha256_file(tmp_path / "none.pt")
    fifo = tmp_path / "fifo.pt"
    os.mkfifo(fifo)
    with within_seconds(10), pytest.raises(userfiles.UserFileError, match=r"a FIFO \(named pipe\)"):
        sha256_file(fifo, what="model file")
    assert userfiles.MAX_MODEL_BYTES == userfiles.MAX_HASHED_BYTES == 8 << 30


def test_read_json_names_the_file(tmp_path):
    bad = tmp_path / "m.json"
    bad.write_text("{nope", encoding="utf-8")
    with pytest.raises(userfiles.UserFileError, match=r"m\.json: the scene meta file is not valid JSON"):
        userfiles.read_json(bad, what="scene meta file", max_bytes=100)
    bad.write_text("[" * 100 + "]" * 100, encoding="utf-8")
    with pytest.raises(userfiles.UserFileError, match="nested more than 32 levels"):
        userfiles.read_json(bad, what="scene meta file", max_bytes=1000)


# -- scene meta ------------------------------------------------------------------------------------
def test_scene_meta_that_is_a_fifo_or_dev_zero_is_passed_over_never_read(tmp_path):
    from assurance.dataio.poses import meta_pose, read_meta
    from assurance.evidence.records import scene_meta

    meta = tmp_path / "seq00" / "meta"
    meta.mkdir(parents=True)
    (meta / "000000.json").write_text(json.dumps({"seed": 5, "pose": {"height_m": 50, "pitch_deg": 45}}))
    os.mkfifo(meta / "000001.json")
    (meta / "000002.json").symlink_to("/dev/zero")
    (meta / "000003.json").symlink_to("/proc/self/environ")
    (meta / "000004.json").write_bytes(b" " * (userfiles.MAX_META_BYTES + 1))
    with within_seconds(10):
        assert scene_meta(tmp_path) == [{"seed": 5, "pose": {"height_m": 50, "pitch_deg": 45}}]
        for name, why in (("000001", "a FIFO"), ("000002", "a character device"), ("000003", "under /proc"),
                          ("000004", "exceeds the limit")):
            with pytest.raises(userfiles.UserFileError, match=why):
                read_meta(meta / f"{name}.json")
        assert meta_pose(meta / "000000.json").height_m == 50
        assert meta_pose(meta / "000001.json") is None  # not a meta file: never opened
        with pytest.raises(ValueError, match="under /proc"):
            meta_pose(meta / "000003.json")
    with pytest.raises(FileNotFoundError):
        read_meta(meta / "none.json")


# -- model files a manifest records ----------------------------------------------------------------
def test_recorded_model_files_under_proc_or_fifos_are_gate_problems(tmp_path):
    from assurance.campaign.model_files import changed_model_files

    fifo = tmp_path / "net.pt"
    os.mkfifo(fifo)
    same = tmp_path / "ok.pt"
    same.write_bytes(b"weights")
    recorded = {"/proc/self/pagemap": "0" * 64, str(fifo): "0" * 64, str(tmp_path / "gone.pt"): "0" * 64,
                str(same): hashlib.sha256(b"weights").hexdigest()}
    with within_seconds(20):
        problems, unchecked = changed_model_files(recorded)
    assert unchecked == [str(tmp_path / "gone.pt")]
    assert len(problems) == 2 and all("refused unread" in p for p in problems)
    assert problems[0].startswith("/proc/self/pagemap: ") and "under /proc" in problems[0]
    assert problems[1].startswith(f"{fifo}: ") and "a FIFO" in problems[1]


# -- readout tables --------------------------------------------------------------------------------
def _run(tmp_path: Path, rows: list[int], monitors: int = 1) -> Path:
    import pyarrow as pa
    import pyarrow.parquet as pq

    run = tmp_path / "run"
    names = [f"t{i}" for i in range(len(rows))]
    (run / "shards").mkdir(parents=True)
    (run / "manifest.json").write_text(json.dumps({"config": {"monitors": ["lhd"] * monitors},
                                                   "tasks": len(rows), "shard_order": names}))
    for name, n in zip(names, rows, strict=True):
        (run / "shards" / name).mkdir()
        for table in ("images", "candidates"):
            pq.write_table(pa.table({"key": pa.array([name] * n), "rank": pa.array(range(n))}),
                           run / "shards" / name / f"{table}.parquet")
    return run


def test_table_caps_follow_the_manifest():
    from assurance.campaign import readouts

    per = readouts.MAX_CANDIDATES_PER_FRAME
    assert readouts.table_caps({"config": {"monitors": ["a", "b"]}, "tasks": 3}) == (2 * per, 6 * per)
    assert readouts.table_caps({"config": {"monitors": ["a"]}, "tasks": 1, "shard_order": ["x"] * 5}) == (per, 5 * per)
    assert readouts.table_caps({}) == (per, per)  # a manifest without them: one task, one configuration
    assert readouts.table_caps({"config": {"monitors": ["a"] * 10}, "tasks": 10 ** 9}) == (
        10 * per, readouts.MAX_RUN_ROWS)  # the absolute cap holds whatever the manifest says


def test_a_table_past_its_row_cap_is_refused_before_it_is_loaded(tmp_path, monkeypatch):
    from assurance.campaign import readouts

    per = readouts.MAX_CANDIDATES_PER_FRAME
    run = _run(tmp_path, [3, per + 1])
    with pytest.raises(readouts.RunError, match=f"{per + 1} rows exceeds the limit of {per} rows for one task"):
        readouts.load_table(run, "candidates")

    def decode(*args):
        raise AssertionError("decoded before the footer was checked")

    with monkeypatch.context() as m:
        m.setattr(readouts, "_decode_table", decode)
        with pytest.raises(readouts.RunError, match="rows exceeds the limit"):
            readouts.read_table_file(run / "shards" / "t1" / "candidates.parquet", max_rows=per)
    small = _run(tmp_path / "small", [3, 4])
    assert len(readouts.load_table(small, "candidates")) == 7
    monkeypatch.setattr(readouts, "MAX_RUN_ROWS", 5)
    with pytest.raises(readouts.RunError, match="tables hold more than 5 rows together"):
        readouts.load_table(small, "candidates")


def test_a_table_that_is_a_link_out_of_the_run_or_a_fifo_is_refused(tmp_path):
    from assurance.campaign import readouts

    run = _run(tmp_path, [2])
    table = run / "shards" / "t0" / "candidates.parquet"
    outside = tmp_path / "elsewhere.parquet"
    table.rename(outside)
    table.symlink_to(outside)
    with pytest.raises(readouts.RunError, match="outside its folder"):
        readouts.load_table(run, "candidates")
    (run / "shards" / "t0" / readouts.SUMS).write_text(f"{'0' * 64}  images.parquet\n{'0' * 64}  candidates.parquet\n")
    assert readouts.check_shard(run, "t0") == "images.parquet differs from its SHA256SUMS (altered or truncated)"
    (run / "shards" / "t0" / readouts.SUMS).write_text(
        f"{sha256_file(run / 'shards' / 't0' / 'images.parquet')}  images.parquet\n{'0' * 64}  candidates.parquet\n")
    why = readouts.check_shard(run, "t0")
    assert why.startswith("candidates.parquet unreadable (") and "outside its folder" in why
    table.unlink()
    os.mkfifo(table)
    with within_seconds(10), pytest.raises(readouts.RunError, match="a FIFO"):
        readouts.load_table(run, "candidates")


# -- the hierarchy a label set names ---------------------------------------------------------------
def test_a_hierarchy_file_out_of_the_label_sets_folder_or_a_fifo_is_refused(tmp_path):
    from el.classes.labels import UAVID, load_label_set
    from el.monitors.hierarchy import ClassHierarchy

    (tmp_path / "tree.yaml").write_text("root: any\nchildren:\n  any: [safe, unsafe]\n"
                                        "  safe: [clutter, tree, low_vegetation, human]\n"
                                        "  unsafe: [building, road, static_car, moving_car]\n")
    sets = tmp_path / "sets"
    sets.mkdir()
    text = (Path(__file__).resolve().parents[1] / "el" / "data" / "labels" / "uavid.yaml").read_text("utf-8")
    for ref in ("../tree.yaml", "linked.yaml"):
        (sets / "linked.yaml").unlink(missing_ok=True)
        (sets / "linked.yaml").symlink_to(tmp_path / "tree.yaml")
        (sets / "mine.yaml").write_text(text.replace("name: uavid", "name: mine") + f"\nhierarchy: {ref}\n")
        with pytest.raises(ValueError, match="outside its folder"):
            load_label_set(sets / "mine.yaml")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    with within_seconds(10), pytest.raises(ValueError, match=r"fifo\.yaml: a FIFO"):
        ClassHierarchy.from_yaml(fifo, labels=UAVID)


# -- the working folder is not on sys.path ---------------------------------------------------------
SHADOW = "import pathlib\npathlib.Path(__file__).with_name('IMPORTED').write_text('x')\nraise SystemExit(99)\n"


def test_python_m_assurance_imports_no_module_of_the_working_folder(tmp_path):
    """A jsonschema.py (and a conftest.py) in the folder ``python -m assurance verify`` runs from are never
    imported: loading ./uav-el.toml imports jsonschema, which is the library's."""
    (tmp_path / "jsonschema.py").write_text(SHADOW, encoding="utf-8")
    (tmp_path / "conftest.py").write_text(SHADOW, encoding="utf-8")
    (tmp_path / "uav-el.toml").write_text('format = "uav-el-system/1"\n', encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSAFEPATH")}
    code = ("import runpy, sys; sys.argv = ['assurance', 'verify', 'no-run']; "
            "runpy.run_module('assurance', run_name='__main__', alter_sys=True)")
    for argv in ([sys.executable, "-m", "assurance", "verify", "no-run"],
                 [sys.executable, "-c", f"import sys; sys.path.insert(0, ''); {code}"]):
        proc = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert "no-run: not a campaign run" in proc.stderr
        assert not (tmp_path / "IMPORTED").exists(), argv


def test_python_m_assurance_still_runs_from_the_source_tree():
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-m", "assurance", "--version"], cwd=root, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.startswith("uav-el "), proc.stderr


def test_the_verify_session_is_rooted_in_the_toolkit_not_the_working_folder(tmp_path, monkeypatch):
    """``uav-el verify``'s pytest session: rootdir the install root (the applicant's conftest.py and ini files are
    not read), no argument naming the working folder."""
    import argparse

    from assurance.cli.verify_run import pytest_args
    from assurance.code_identity import install_root

    monkeypatch.chdir(tmp_path)
    args = argparse.Namespace(run=str(tmp_path / "run"), tests=[], registry=None, targets=None, keyword=None)
    argv = pytest_args(args, tmp_path / "out")
    assert argv[argv.index("--rootdir") + 1] == str(install_root())
    assert str(tmp_path) not in argv[0] and "no:cacheprovider" in argv


# -- small items -----------------------------------------------------------------------------------
def test_braces_in_a_system_fact_are_literal_text(tmp_path):
    from assurance.requirements import load_registry
    from assurance.requirements.system_facts import facts_of_file, shipped_facts
    from assurance.system import find_system

    path = tmp_path / "sys.toml"
    path.write_text('format = "uav-el-system/1"\n[camera]\nname = "Cam {A}"\n', encoding="utf-8")
    system = find_system(str(path))
    reg = load_registry(None).for_system(facts_of_file(system))
    assert "camera 'Cam {A}'" in " ".join(reg.operating_domain.values())
    assert reg.facts["camera"].startswith("camera 'Cam {A}'")
    facts = {**shipped_facts(), "forbidden": "{confidence:pct} x", "label_set": "{0}"}
    reg = load_registry(None).for_system(facts)
    texts = " ".join(f"{r.title} {r.text} {r.acceptance} {r.domain}" for r in reg)
    assert "{confidence:pct} x" in texts and "95% x" not in texts
    domain = " ".join(reg.operating_domain.values())
    assert "errors up to 20% in height and 20% in pitch" in domain  # the toolkit's own pose wording: rendered


def test_an_impossible_waiver_date_names_the_file_and_the_waiver(tmp_path, capsys):
    from assurance.cli import main
    from assurance.evidence.waivers import load_waivers

    path = tmp_path / "waivers.yaml"
    body = "waivers:\n  - id: EL-R10\n    reason: later\n    tracked_by: none\n    owner: me\n    expires: {}\n"
    path.write_text(body.format("2026-02-30"), encoding="utf-8")
    with pytest.raises(ValueError, match=rf"{path}: waiver 1 \(EL-R10\): expires must be a date .*'2026-02-30': not "
                                         r"a date of the calendar \(day is out of range for month\)"):
        load_waivers(path)
    path.write_text(body.format("2026-2-3"), encoding="utf-8")
    assert load_waivers(path)["EL-R10"]["expires"] == "2026-02-03"  # as YAML read it before
    path.write_text(body.format("'2026-03-01'"), encoding="utf-8")
    assert load_waivers(path)["EL-R10"]["expires"] == "2026-03-01"
    path.write_text(body.format("2026-02-30"), encoding="utf-8")
    run = tmp_path / "run"
    run.mkdir()
    (run / "manifest.json").write_text("{}")
    assert main(["evidence", "--run", str(run), "--out", str(tmp_path / "rep"), "--waivers", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "waivers.yaml: waiver 1 (EL-R10)" in err, err
