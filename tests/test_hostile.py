"""The hostile-user cases 4-8, replayed through the command line (cases 1-2: tests/test_evidence.py,
case 3: tests/test_budget.py): each now ends in one clear line and a distinct exit code, never a traceback."""

from __future__ import annotations

import io
import json
import os
import shutil
import stat

import pytest
import torch

from assurance.campaign import readouts
from assurance.cli import EXIT_BAD_INPUT, EXIT_DAMAGED_RUN, main

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def cli(capsys, *args) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    return code, out.out, out.err


@pytest.fixture(scope="module")
def small(tiny_campaign, tmp_path_factory):
    """A finished 2-image campaign of the tiny CNN, run through the command line."""
    root = tmp_path_factory.mktemp("hostile")
    run = root / "run"
    code = main(["campaign", "--data", str(tiny_campaign["data"]), "--out", str(run), "--weights",
                 str(tiny_campaign["weights"]), "--perturbations", "none", "--monitors", "lhd", "--images", "2",
                 "--quiet"])
    assert code == 0
    return {"run": run, "data": tiny_campaign["data"], "weights": tiny_campaign["weights"], "root": root}


def campaign_args(small, run, *extra):
    return ("campaign", "--data", small["data"], "--out", run, "--weights", small["weights"], "--perturbations",
            "none", "--monitors", "lhd", "--images", "2", "--quiet", *extra)


def copy_run(small, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small["run"], run)
    return run, sorted(p for p in (run / "shards").iterdir())


def test_case_4_truncated_shard_is_not_done_and_is_run_again(small, tmp_path, capsys):
    run, shards = copy_run(small, tmp_path)
    f = shards[0] / "images.parquet"
    f.write_bytes(f.read_bytes()[:100])
    assert not readouts.shard_done(run, shards[0].name)
    code, out, err = cli(capsys, *(a for a in campaign_args(small, run) if a != "--quiet"))
    assert code == 0
    assert "1 task(s) run, 1 already done, of 2" in out
    assert f"{shards[0].name}: images.parquet differs from its SHA256SUMS (altered or truncated)" in err
    assert readouts.shard_done(run, shards[0].name)
    assert cli(capsys, "table", run, "--boot", 20)[0] == 0


def test_case_5_negative_seed_is_refused_and_faulted_runs_read(small, tmp_path, capsys):
    run = tmp_path / "neg"
    code, _, err = cli(capsys, *campaign_args(small, run, "--seed", "-1"))
    assert code == EXIT_BAD_INPUT and "seed must be an integer >= 0, got -1" in err
    assert not run.exists()
    # a run whose every task faulted: table and evidence read it (no KeyError), evidence says nothing verified
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign

    class Broken:
        def predict_frame(self, rgb):
            raise RuntimeError("broken segmenter")

        predict_patch = mc_dropout = predict_frame

    faulted = tmp_path / "faulted"
    summary = run_campaign(small["data"], faulted, CampaignConfig(perturbations=("none", "fog"), monitors=("lhd",),
                                                                  images=2), segmenter=Broken(),
                           execution=Execution(progress=False))
    assert len(summary["faults"]) == 4
    code, _, err = cli(capsys, "table", faulted, "--boot", 20)
    assert code == 0 and "faulted task(s) are left out" in err
    code, out, _ = cli(capsys, "evidence", "--run", faulted, "--out", tmp_path / "rep", "--no-pdf", "--boot", 20)
    assert code == 1 and "not verified:  17" in out and "gate: FAILED (not verified" in out


def test_case_6_deleted_shard_folder_is_a_damaged_run(small, tmp_path, capsys):
    run, shards = copy_run(small, tmp_path)
    shutil.rmtree(shards[1])
    code, out, err = cli(capsys, "table", run, "--boot", 20)
    assert code == EXIT_DAMAGED_RUN == 4
    assert f"damaged run, 1 shard problem(s): shard {shards[1].name}: shard folder missing" in err
    assert not (run / "results.csv").exists()
    code, out, err = cli(capsys, *campaign_args(small, run))  # --quiet: the repair is a warning, on stderr
    assert code == 0 and f"{shards[1].name}: shard folder missing" in err
    assert cli(capsys, "table", run, "--boot", 20)[0] == 0


def test_case_7_no_tracebacks_for_bad_output_paths(small, tmp_path, capsys):
    image = next((small["data"] / "seq00" / "Images").iterdir())
    js = tmp_path / "d.json"
    code, _, err = cli(capsys, "land", image, "--weights", small["weights"], "--json", js,
                       "--overlay", tmp_path / "out.xyz")
    assert code == EXIT_BAD_INPUT and "--overlay" in err and "unknown image type '.xyz'" in err
    assert not js.exists()  # refused before anything was written
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    code, _, err = cli(capsys, *campaign_args(small, afile))
    assert code == EXIT_BAD_INPUT and f"{afile}: exists and is not a folder" in err
    assert afile.read_text() == "x"


def test_case_8_json_dir_bad_weights_pickle_and_file_modes(small, tmp_path, capsys):
    image = next((small["data"] / "seq00" / "Images").iterdir())
    code, _, err = cli(capsys, "land", image, "--json", tmp_path)
    assert code == EXIT_BAD_INPUT and f"--json {tmp_path}: is a folder" in err
    # a campaign refused for bad weights leaves no run folder, so the good weights then run
    bad = tmp_path / "bad.pt"
    shutil.copy(small["weights"], bad)
    shutil.copy(small["weights"].with_suffix(".json"), bad.with_suffix(".json"))
    bad.write_bytes(bad.read_bytes() + b"x")
    run = tmp_path / "run"
    code, _, err = cli(capsys, "campaign", "--data", small["data"], "--out", run, "--weights", bad,
                       "--perturbations", "none", "--monitors", "lhd", "--images", "1", "--quiet")
    assert code == EXIT_BAD_INPUT and "SHA-256 mismatch" in err and not run.exists()
    # a pickle bomb (its card records its hash): refused without torch's "weights_only=False" advice
    class Evil:
        def __reduce__(self):
            return (os.system, ("echo pwned",))

    buf = io.BytesIO()
    torch.save({"x": Evil()}, buf)
    bad.write_bytes(buf.getvalue())
    card = json.loads(bad.with_suffix(".json").read_text())
    import hashlib

    card["weights_sha256"] = hashlib.sha256(buf.getvalue()).hexdigest()
    bad.with_suffix(".json").write_text(json.dumps(card))
    code, out, err = cli(capsys, "land", image, "--weights", bad)
    assert code == EXIT_BAD_INPUT and "refused: the file holds pickled objects" in err
    assert "weights_only=False" not in err and "set to `False`" not in err and "pwned" not in out
    # files are written 0666 less the umask (mkstemp alone would give 0600)
    old = os.umask(0o027)
    try:
        code, _, _ = cli(capsys, "land", image, "--weights", small["weights"], "--monitor", "lhd", "--json",
                         tmp_path / "m.json", "--overlay", tmp_path / "m.png")
        assert code == 0
        for f in ("m.json", "m.png"):
            assert stat.S_IMODE((tmp_path / f).stat().st_mode) == 0o640
    finally:
        os.umask(old)
    for f in [small["run"] / "manifest.json", small["run"] / readouts.INDEX,
              *(small["run"] / "shards").rglob("*")]:
        assert stat.S_IMODE(f.stat().st_mode) & 0o044 == 0o044, f  # readable by others under umask 022
