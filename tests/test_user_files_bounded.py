"""The trust boundary: every file a user hands the toolkit is read bounded (``el.base.userfiles``), and what
it says is checked before any work starts.

A FIFO, a device or a folder is refused before a read that could block; a file over its kind's cap is refused
before it is read; a TOML or JSON nested thousands deep is refused without a RecursionError; NaN in a system file
is refused when it is loaded; a signing key others can read is refused with the fix; a report is never written
inside a run; a waiver cannot expire at version 999; the report names tasks the manifest plans but the run lacks;
a re-hashed gate or card whose threshold lies outside its fit's scores is refused when the system is built, a
``--gate`` as one a system file names; a report template, a gate or card, or a ``uav-el.toml`` here that is a FIFO
is refused naming it, never read, skipped or reported missing.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from helpers import within_seconds as within

from assurance.cli import main
from el.base import userfiles

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs (POSIX)")


def one_line(capsys, *needles: str) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


@pytest.fixture
def fifo(tmp_path) -> Path:
    path = tmp_path / "pipe.yaml"
    os.mkfifo(path)
    return path


def system_file(folder: Path, body: str, name: str = "uav-el.toml") -> Path:
    path = folder / name
    path.write_text('format = "uav-el-system/1"\n' + body, encoding="utf-8")
    return path


# -- the reader ------------------------------------------------------------------------------------
def test_the_reader_refuses_what_is_not_a_regular_file_before_reading(tmp_path, fifo):
    zero = tmp_path / "zero.yaml"
    zero.symlink_to("/dev/zero")
    (tmp_path / "folder.yaml").mkdir()
    with within(10):
        for path, kind in ((fifo, r"a FIFO \(named pipe\)"), (zero, "a character device"),
                           (tmp_path / "folder.yaml", "a folder")):
            with pytest.raises(userfiles.UserFileError, match=f"{path.name}: {kind}, not a regular file"):
                userfiles.read_bytes(path, what="label set file", max_bytes=100)
    with pytest.raises(userfiles.UserFileError, match="no such file"):
        userfiles.read_text(tmp_path / "none.yaml", what="waivers file", max_bytes=100)
    small = tmp_path / "small.txt"
    small.write_bytes(b"x" * 100)
    assert userfiles.read_bytes(small, what="file", max_bytes=100) == b"x" * 100
    with pytest.raises(userfiles.UserFileError, match="101 bytes exceeds the limit of 100 bytes"):
        small.write_bytes(b"x" * 101)
        userfiles.read_bytes(small, what="file", max_bytes=100)


def test_fifos_and_dev_zero_as_labels_waivers_targets_registry_and_poses_are_refused_at_once(tmp_path, fifo, capsys):
    from assurance.dataio.poses import read_poses
    from assurance.evidence.waivers import load_waivers
    from assurance.requirements import RegistryError, TargetError, load_registry, read_targets_file
    from el.base.errors import DataError
    from el.classes.labels import load_label_set

    zero = tmp_path / "labels.yaml"
    zero.symlink_to("/dev/zero")
    t0 = time.monotonic()
    with within(20):
        with pytest.raises(ValueError, match="a FIFO"):
            load_label_set(fifo)
        with pytest.raises(ValueError, match="a character device"):
            load_label_set(zero)  # it grew to 6.5 GB before a MemoryError
        with pytest.raises(ValueError, match="pipe.yaml: .*a FIFO"):
            load_waivers(fifo)
        with pytest.raises(RegistryError, match="a FIFO"):
            load_registry(fifo)
        with pytest.raises(DataError, match="a FIFO"):
            read_poses(fifo)
        pipe_json = tmp_path / "targets.json"
        os.mkfifo(pipe_json)
        with pytest.raises(TargetError, match="targets.json: a FIFO"):
            read_targets_file(pipe_json)
        system = system_file(tmp_path, f'[labels]\nfile = "{fifo}"\n')
        assert main(["land", "--system", str(system), str(tmp_path / "x.png")]) == 2
        one_line(capsys, str(system), "labels.file", "a FIFO")
        pipe_system = tmp_path / "pipe.toml"
        os.mkfifo(pipe_system)
        assert main(["land", "--system", str(pipe_system), str(tmp_path / "x.png")]) == 2
        one_line(capsys, "pipe.toml: a FIFO")
    assert time.monotonic() - t0 < 20


def test_oversized_files_are_refused_before_they_are_read(tmp_path, capsys):
    from assurance.dataio.poses import read_poses
    from el.base.errors import DataError

    poses = tmp_path / "poses.csv"
    with open(poses, "wb") as f:
        f.truncate(200 << 20)  # 200 MB, sparse: it took 3.5 GB to read
    t0 = time.monotonic()
    with pytest.raises(DataError, match=f"209715200 bytes exceeds the limit of {userfiles.MAX_POSES_BYTES} bytes"):
        read_poses(poses)
    assert time.monotonic() - t0 < 2
    big = tmp_path / "big.toml"
    big.write_text('format = "uav-el-system/1"\n#' + "x" * 1_000_000 + "\n")
    assert main(["land", "--system", str(big), str(tmp_path / "x.png")]) == 2
    one_line(capsys, "big.toml", "exceeds the limit of 1000000 bytes for a system file")


def test_a_poses_file_at_its_cap_reads_in_bounded_time(tmp_path):
    from assurance.dataio.poses import read_poses

    path = tmp_path / "poses.csv"
    line = "{:07d},50.0,45.0\n"
    n = (userfiles.MAX_POSES_BYTES - 30) // len(line.format(0))
    path.write_text("frame,height_m,pitch_deg\n" + "".join(line.format(i) for i in range(n)), encoding="utf-8")
    t0 = time.monotonic()
    assert len(read_poses(path)) == n
    assert time.monotonic() - t0 < 30


# -- nesting and numbers ---------------------------------------------------------------------------
@pytest.mark.parametrize("body", ["x = " + "[" * 60_000 + "]" * 60_000, "x = " + "{a = " * 60_000 + "1" + "}" * 60_000,
                                  ".".join(["a"] * 100_000) + " = 1", ".".join(['"a"'] * 50_000) + " = 1"],
                         ids=["brackets", "braces", "dotted-key", "quoted-dotted-key"])
def test_a_deeply_nested_toml_is_refused_cleanly_and_fast(tmp_path, capsys, body):
    path = system_file(tmp_path, body + "\n")
    t0 = time.monotonic()
    with within(20):
        assert main(["land", "--system", str(path), str(tmp_path / "x.png")]) == 2
    assert time.monotonic() - t0 < 5  # was exit 70 (RecursionError), or minutes for a 100 000-part dotted key
    one_line(capsys, str(path), "nested more than")


def test_toml_nesting_skips_strings_and_comments():
    assert userfiles.toml_nesting('a = "[[[[a.b.c.d.e.f" # [[[[\nb = [[1, 2], [3]]\nc.d.e = 1.5\n') == 3
    assert userfiles.toml_nesting("'''\n[[[[[[\n'''\nx = 1\n") == 0
    assert userfiles.toml_nesting('"' * 200_000) == 0  # unterminated strings: linear, not quadratic


def test_deep_json_and_yaml_are_refused_without_a_recursion_error(tmp_path):
    from assurance.requirements import TargetError, read_targets_file
    from el.base import safeyaml
    from el.classes.labels import load_label_set

    (tmp_path / "t.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(TargetError, match="t.json: nested too deeply"):
        read_targets_file(tmp_path / "t.json")
    (tmp_path / "l.json").write_text('{"a": ' * 40 + "1" + "}" * 40)
    with pytest.raises(ValueError, match="l.json: nested more than 32 levels"):
        load_label_set(tmp_path / "l.json")
    with pytest.raises(safeyaml.YamlLimitError, match="nested"):
        safeyaml.safe_load("a: " + "[" * 50_000 + "]" * 50_000)


@pytest.mark.parametrize("key, value", [("targets.unsafe_landing_bound", "nan"), ("safety.radius_m", "nan"),
                                        ("camera.height_m", "nan"), ("camera.pitch_deg", "-inf")])
def test_nan_and_infinity_in_a_system_file_are_refused_when_it_is_loaded(tmp_path, capsys, key, value):
    section, name = key.split(".")
    path = system_file(tmp_path, f"[{section}]\n{name} = {value}\n")
    assert main(["land", "--system", str(path), str(tmp_path / "x.png")]) == 2
    one_line(capsys, str(path), f"{key} = {value.lstrip('+')}: must be a finite number")


@pytest.mark.parametrize("section, name, text", [("system", "name", "orchard \\u202eDELIAF\\u202c"),
                                                 ("report", "title", "Evidence\\u200b report"),
                                                 ("report", "organisation", "ACME\\u0007")])
def test_invisible_characters_in_a_system_file_are_refused(tmp_path, capsys, section, name, text):
    # a right-to-left override makes "DELIAF" display as "FAILED" on the report's first page
    path = system_file(tmp_path, f'[{section}]\n{name} = "{text}"\n')
    assert main(["land", "--system", str(path), str(tmp_path / "x.png")]) == 2
    one_line(capsys, str(path), f"{section}.{name}: holds the invisible character U+")


@pytest.mark.parametrize("manifest", ["[" * 100_000 + "]" * 100_000, "[]", '{"system": "x"}',
                                      '{"system": {"default": false, "document": "x"}}'])
def test_a_damaged_run_manifest_is_one_line_not_an_internal_error(tmp_path, capsys, manifest):
    run = tmp_path / "run"
    run.mkdir()
    (run / "manifest.json").write_text(manifest)
    for command in (["verify", str(run), "--out", str(tmp_path / "v")],
                    ["evidence", "--run", str(run), "--out", str(tmp_path / "e"), "--no-pdf"]):
        assert main(command) not in (0, 70)
        one_line(capsys, str(run))


def test_a_deeply_nested_envelope_is_refused_as_such(tmp_path):
    from assurance.attest import AttestationError
    from assurance.attest.dsse import read_envelope

    (tmp_path / "campaign.dsse.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(AttestationError, match="nested too deeply"):
        read_envelope(tmp_path / "campaign.dsse.json")


def test_a_nan_target_is_refused_before_a_campaign_starts(tmp_path, capsys):
    path = system_file(tmp_path, "[targets]\nunsafe_landing_bound = nan\n")
    out = tmp_path / "run"
    assert main(["campaign", "--system", str(path), "--data", str(tmp_path), "--out", str(out)]) == 2
    one_line(capsys, "unsafe_landing_bound = nan: must be a finite number")
    assert not out.exists()  # refused before the run folder was made (it was refused after the run was signed)


# -- keys, the report's folder, waivers, missing tasks ---------------------------------------------
def test_a_signing_key_others_can_read_is_refused_with_the_fix(tmp_path):
    from assurance.attest import AttestationError
    from assurance.attest.keys import create_key, load_signing_key

    key = tmp_path / "key.pem"
    made = create_key(key)
    assert load_signing_key(key).keyid == made.keyid  # 0600
    key.chmod(0o644)
    with pytest.raises(AttestationError, match=rf"mode 0644.*chmod 600 {key}"):
        load_signing_key(key)
    key.chmod(0o640)
    with pytest.raises(AttestationError, match="chmod 600"):
        load_signing_key(key)


def test_a_report_inside_a_run_folder_is_refused(tmp_path, capsys):
    run = tmp_path / "run"
    (run / "shards").mkdir(parents=True)
    (run / "manifest.json").write_text("{}")
    for out in (run / "shards" / "report", run, run / "report"):
        assert main(["evidence", "--run", str(run), "--out", str(out), "--no-pdf"]) == 2
        one_line(capsys, f"--out {out}: lies inside the campaign run")
        assert not (run / "shards" / "report").exists()
    other = tmp_path / "other-run"
    (other / "shards").mkdir(parents=True)
    (other / "manifest.json").write_text("{}")
    assert main(["evidence", "--run", str(run), "--out", str(other / "x"), "--no-pdf"]) == 2
    one_line(capsys, f"lies inside the campaign run {other}")


def test_a_waiver_expires_at_most_at_the_next_minor_release():
    from assurance.evidence.waivers import max_expiry_version, waiver_problems

    assert max_expiry_version("0.1.0") == (0, 2, 0) and max_expiry_version("1.3.7") == (1, 4, 0)
    states = {"EL-R10": "failed"}
    far = waiver_problems({"EL-R10": {"owner": "x", "expires": "999.0.0"}}, states, version="0.1.0")
    assert len(far) == 1 and "expires at version 999.0.0, beyond the next minor release 0.2.0" in far[0]
    assert waiver_problems({"EL-R10": {"owner": "x", "expires": "0.2.0"}}, states, version="0.1.0") == []
    assert waiver_problems({"EL-R10": {"owner": "x", "expires": "0.2.1"}}, states, version="0.1.0")


def test_tasks_the_manifest_names_without_readouts_are_named(tmp_path):
    from assurance.campaign.integrity import verify_run

    run = tmp_path / "run"
    (run / "shards").mkdir(parents=True)
    (run / "manifest.json").write_text(json.dumps({"shard_order": ["none-s3__a-1", "none-s3__b-2"]}))
    check = verify_run(run)
    assert check.missing == ["none-s3__a-1", "none-s3__b-2"]
    line = check.missing_problems()
    assert len(line) == 1 and "names 2 of its 2 task(s) with no readouts (none-s3__a-1, none-s3__b-2)" in line[0]


# -- fitted files ----------------------------------------------------------------------------------
def _resealed(src: Path, dst: Path, **body) -> Path:
    from el.base.records import body_sha256

    doc = json.loads(src.read_text(encoding="utf-8"))
    doc["body"].update(body)
    doc["sha256"] = body_sha256(doc["body"])
    dst.write_text(json.dumps(doc), encoding="utf-8")
    return dst


def test_a_resealed_gate_or_card_threshold_outside_its_fit_is_refused_at_load(tmp_path, capsys):
    from el.flight.pipeline import DEPLOYED_CALIBRATION, DEPLOYED_GATE

    gate = _resealed(Path(DEPLOYED_GATE), tmp_path / "gate.json", threshold=1e300)
    path = system_file(tmp_path, f'[monitor]\ngate = "{gate.name}"\n', "gate.toml")
    assert main(["land", "--system", str(path), str(tmp_path / "x.png")]) == 2
    one_line(capsys, "monitor.gate", "gate.json: threshold 1e+300 lies above the highest score")
    monitor = json.loads(Path(DEPLOYED_CALIBRATION).read_text())["body"]["monitor"]
    card = _resealed(Path(DEPLOYED_CALIBRATION), tmp_path / "card.json", threshold=1e300,
                     spec=f"{monitor},threshold=1e+300")
    path = system_file(tmp_path, f'[monitor]\ncalibration = "{card.name}"\n', "card.toml")
    assert main(["land", "--system", str(path), str(tmp_path / "x.png")]) == 2
    one_line(capsys, "monitor.calibration", "card.json: threshold 1e+300 lies outside the score range [0, 1]")
    fine = _resealed(Path(DEPLOYED_GATE), tmp_path / "fine.json", threshold=20.0)  # inside [median, max]
    from assurance.system.sense import gate_problem

    assert gate_problem(fine) is None


def test_a_resealed_gate_given_on_the_command_line_is_refused_when_the_system_is_built(tiny_campaign, tmp_path,
                                                                                      capsys):
    from assurance.system import SystemFileError, default_system
    from assurance.system.system import System
    from el.flight.pipeline import DEPLOYED_GATE

    gate = _resealed(Path(DEPLOYED_GATE), tmp_path / "gate-1e300.json", threshold=1e300)
    with pytest.raises(SystemFileError, match=f"--gate {gate}: threshold 1e\\+300 lies above the highest score"):
        System.build(default_system(), gate=gate)  # it was checked only when a system file named it
    image = next(tiny_campaign["data"].glob("**/Images/*.png"))
    assert main(["land", str(image), "--monitor", "lhd", "--gate", str(gate)]) == 2
    one_line(capsys, f"--gate {gate}: threshold 1e+300 lies above the highest score")
    pipe = tmp_path / "gate-fifo.json"
    os.mkfifo(pipe)
    with within(10):
        assert main(["land", str(image), "--monitor", "lhd", "--gate", str(pipe)]) == 2
    one_line(capsys, f"--gate {pipe}: a FIFO (named pipe), not a regular file")


# -- templates and what a system file names --------------------------------------------------------
def test_a_template_that_is_a_fifo_or_dev_zero_is_refused_naming_it(tmp_path, fifo):
    from assurance.evidence.render import TemplateError, _render, environment

    folder = tmp_path / "tpl"
    folder.mkdir()
    fifo.rename(folder / "auditor_issre.html.j2")
    (folder / "evidence.css").symlink_to("/dev/zero")
    env = environment(folder)
    with within(10):
        for name, kind in (("auditor_issre.html.j2", r"a FIFO \(named pipe\)"), ("evidence.css", "a character device")):
            with pytest.raises(userfiles.UserFileError, match=f"{name}: {kind}, not a regular file"):
                env.get_template(name)  # Jinja's own loader passed over it for the packaged one
        with pytest.raises(TemplateError, match=r"auditor_issre.html.j2: a FIFO \(named pipe\)"):
            _render(env, "auditor_issre.html.j2", {})  # one line naming it, not a rendering failure
    assert env.get_template("macros.html.j2").filename.endswith("evidence_templates/macros.html.j2")  # a gap


def test_evidence_with_a_fifo_template_is_exit_2_naming_it(tiny_campaign, tmp_path, fifo, capsys):
    folder = tmp_path / "tpl"
    folder.mkdir()
    fifo.rename(folder / "auditor_issre.html.j2")
    with within(60):
        assert main(["evidence", "--run", str(tiny_campaign["run"]), "--out", str(tmp_path / "r"), "--no-pdf",
                     "--boot", "20", "--templates", str(folder)]) == 2
    one_line(capsys, "auditor_issre.html.j2: a FIFO (named pipe), not a regular file")


def test_a_uav_el_toml_here_that_is_not_a_regular_file_is_refused_not_passed_over(tmp_path, monkeypatch, capsys):
    from assurance.system import SystemFileError
    from assurance.system.find import find_system

    os.mkfifo(tmp_path / "uav-el.toml")
    with within(10):
        with pytest.raises(SystemFileError, match=r"uav-el.toml: a FIFO \(named pipe\), not a regular file"):
            find_system(cwd=tmp_path)  # it was passed over for the embedded default
        monkeypatch.chdir(tmp_path)
        assert main(["land", str(tmp_path / "x.png")]) == 2
    one_line(capsys, f"{tmp_path / 'uav-el.toml'}: a FIFO")


@pytest.mark.parametrize("key", ["gate", "calibration"])
def test_a_gate_or_card_a_system_file_names_that_is_a_fifo_is_named_as_one(tmp_path, fifo, capsys, key):
    path = system_file(tmp_path, f'[monitor]\n{key} = "{fifo.name}"\n', "sys.toml")
    with within(10):
        assert main(["land", "--system", str(path), str(tmp_path / "x.png")]) == 2
    err = one_line(capsys, str(path), f"monitor.{key}", f"{fifo}: a FIFO (named pipe), not a regular file")
    assert "no such file" not in err
