"""Bounded resources and no silent loss: pixel limit from the header, EXIF orientation, YAML without
aliases, seeds, --jobs, thresholds inside a monitor's score range, the decision's deadline inside stages and
its hard stop, shard names that cannot collide, meta in the data hash, configuration faults, index repair."""

from __future__ import annotations

import json
import shutil
import threading
import time
import warnings

import cv2
import numpy as np
import pytest
from helpers import FakeClock, OracleSegmenter, scene_ids, scene_image

from assurance.campaign import faults, readouts
from assurance.campaign.integrity import verify_run
from assurance.campaign.run import CampaignConfig, Execution, run_campaign
from assurance.cli import main
from assurance.dataio.uavid import image_size, write_image
from assurance.evidence.waivers import load_waivers
from assurance.fault_injection.bounds import YAML_BOMB, _png
from assurance.workers import bounded_jobs, usable_cores
from el.base import deadline as dl
from el.base import safeyaml
from el.base.errors import BudgetExceeded, DataError
from el.base.imageheader import read_header
from el.base.imageio import MAX_PIXELS, read_image, read_image_meta
from el.classes.labels import UAVID
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.config import SEED_LIMIT, CoreConfig, check_seed
from el.landing.core import run_core
from el.monitors import build_monitor

WW = 128


# -- pixel limit and EXIF orientation --------------------------------------------------------------
def test_a_header_claiming_a_huge_frame_is_refused_before_decoding(tmp_path):
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(_png(100_000, 100_000, None))
    assert len(bomb.read_bytes()) < 70
    with pytest.raises(DataError, match=r"bomb.png: image of 100000x100000 pixels exceeds the limit"):
        read_image(bomb)
    with pytest.raises(DataError, match="exceeds the limit"):
        image_size(bomb)
    # in flight: the default action, the reason naming the file
    d = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd"),
                         segmenter=OracleSegmenter(WW)).decide(bomb)
    assert d.action == "default" and "bomb.png" in d.reason and "exceeds the limit" in d.reason
    # the limit is configurable, and an in-memory frame is held to it too
    img = tmp_path / "small.png"
    write_image(img, scene_image(scene_ids()))
    assert read_image(img).shape == (144, 256, 3) and MAX_PIXELS >= 7680 * 4320
    with pytest.raises(DataError, match="exceeds the limit of 1000 pixels"):
        read_image(img, max_pixels=1000)
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", max_pixels=1000)
    d = EmergencyLanding(cfg, segmenter=OracleSegmenter(WW)).decide(scene_image(scene_ids()))
    assert d.action == "default" and "exceeds the limit of 1000 pixels" in d.reason
    with pytest.raises(ValueError, match="max_pixels must be a positive integer"):
        PipelineConfig(max_pixels=0)
    assert main(["land", str(bomb), "--monitor", "lhd"]) == 2


def test_exif_orientation_is_applied_when_the_metadata_runs_past_64_kib(tmp_path):
    """A camera's EXIF (a thumbnail) and an ICC profile put the frame header past the first 64 KiB: the frame was
    decided on sideways, silently."""
    from PIL import Image

    rgb = scene_image(scene_ids())
    exif = Image.Exif()
    exif[0x0112] = 6
    exif[0x010E] = "x" * 58_000  # ImageDescription, as large as a thumbnail
    path = tmp_path / "big.jpg"
    Image.fromarray(rgb).save(path, quality=95, exif=exif.tobytes(), icc_profile=b"\0" * 70_000)
    assert read_header(path.read_bytes()[:1 << 16]) is None  # the header lies past the first 64 KiB
    got, meta = read_image_meta(path)
    assert meta == {"exif_orientation": 6} and got.shape[:2] == (256, 144)
    assert image_size(path) == (144, 256)


def test_jpeg_header_and_exif_orientation_as_opencv_applies_it(tmp_path):
    from PIL import Image

    rgb = scene_image(scene_ids())
    for orientation in range(1, 9):
        exif = Image.Exif()
        exif[0x0112] = orientation
        path = tmp_path / f"o{orientation}.jpg"
        Image.fromarray(rgb).save(path, quality=95, exif=exif.tobytes())
        header = read_header(path.read_bytes())
        assert (header.width, header.height, header.format, header.orientation) == (256, 144, "jpeg", orientation)
        got, meta = read_image_meta(path)
        want = cv2.imread(str(path), cv2.IMREAD_COLOR)[:, :, ::-1]  # OpenCV applies the orientation here
        assert np.array_equal(got, want), orientation
        assert meta == ({} if orientation == 1 else {"exif_orientation": orientation})
        assert image_size(path) == (got.shape[1], got.shape[0])
    d = EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd"),
                         segmenter=OracleSegmenter(WW)).decide(tmp_path / "o3.jpg")
    assert d.input["exif_orientation"] == 3
    png = tmp_path / "plain.png"
    write_image(png, rgb)
    assert read_image_meta(png)[1] == {} and read_header(png.read_bytes()).pixels == 256 * 144


# -- YAML ------------------------------------------------------------------------------------------
def test_yaml_aliases_and_oversized_files_are_refused(tmp_path):
    assert safeyaml.safe_load("a: &x 1\nb: [2, 3]\n") == {"a": 1, "b": [2, 3]}  # an anchor alone is harmless
    with pytest.raises(safeyaml.YamlLimitError, match="aliases are not allowed"):
        safeyaml.safe_load(YAML_BOMB)
    with pytest.raises(safeyaml.YamlLimitError, match="exceeds the limit of 10 bytes"):
        safeyaml.safe_load("a: 12345678901", max_bytes=10)
    big = tmp_path / "big.yaml"
    big.write_text("a: " + "x" * (safeyaml.MAX_YAML_BYTES + 1))
    with pytest.raises(safeyaml.YamlLimitError, match="exceeds the limit"):
        safeyaml.load_file(big)
    w = tmp_path / "waivers.yaml"
    w.write_text(YAML_BOMB + "waivers:\n  - {id: EL-R01, reason: *l8, tracked_by: x, owner: x, expires: 2099-01-01}\n")
    t0 = time.process_time()
    with pytest.raises(ValueError, match="waivers.yaml: unreadable waivers file: .*aliases are not allowed"):
        load_waivers(w)
    assert time.process_time() - t0 < 5  # refused at the first alias, not expanded


# -- seeds, jobs -----------------------------------------------------------------------------------
def test_seeds_outside_0_to_2_32_are_refused_everywhere():
    assert check_seed(0) == 0 and check_seed(SEED_LIMIT - 1) == SEED_LIMIT - 1
    for bad in (-1, SEED_LIMIT, 2**63, 2**64, True, 1.0):
        with pytest.raises(ValueError, match="seed must be an integer >= 0"):
            check_seed(bad)
        with pytest.raises(ValueError, match="seed must be an integer >= 0"):
            PipelineConfig(seed=bad)
        with pytest.raises(ValueError, match="seed must be an integer >= 0"):
            CampaignConfig(perturbations=("none",), seed=bad)


def test_jobs_are_clamped_to_the_cores_with_a_warning():
    cores = usable_cores()
    assert bounded_jobs(1) == 1 and bounded_jobs(cores) == cores
    seen: list[str] = []
    assert bounded_jobs(1000, warn=seen.append) == cores
    assert seen == [f"--jobs 1000 exceeds the {cores} CPU core(s) this process may use; using {cores} worker(s)"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert bounded_jobs(cores + 1) == cores
    assert any("exceeds the" in str(w.message) for w in caught)
    with pytest.raises(ValueError, match="--jobs must be an integer >= 1"):
        bounded_jobs(0)


# -- monitor score ranges --------------------------------------------------------------------------
@pytest.mark.parametrize("spec", ["lhd:threshold=1e300", "lhd:threshold=1", "lhd:threshold=-1.5",
                                  "lhd+ch:tau=0.25,threshold=7", "msp:threshold=2", "entropy:threshold=-0.1",
                                  "lhd+mcd:n=2,rho=0.5,threshold=-3", "lhd+mcd:n=2,rho=0.5,threshold=1"])
def test_a_threshold_outside_the_score_range_is_refused(spec):
    with pytest.raises(ValueError, match="outside the monitor's score range"):
        build_monitor(spec, labels=UAVID)


def test_thresholds_inside_the_range_and_the_paper_grid_are_unchanged():
    from el.monitors import PAPER_GRID

    for spec in PAPER_GRID:
        assert build_monitor(spec, labels=UAVID).name == build_monitor(spec, labels=UAVID).spec.name
    assert build_monitor("lhd:threshold=0.99", labels=UAVID).threshold == 0.99
    assert build_monitor("lhd:threshold=-1", labels=UAVID).threshold == -1.0
    m = build_monitor("lhd+mcd:n=2,rho=0.5,threshold=-2", labels=UAVID)  # MC dropout's wider range: mean + 3 std
    assert m.threshold == -2.0 and m.name == "lhd+mcd:n=2,rho=0.5,threshold=-2.0"
    assert build_monitor("lhd+mcd:n=10,rho=0.9", labels=UAVID).name == "lhd+mcd:n=10,rho=0.9"
    assert build_monitor("msp", labels=UAVID).threshold == 1.0


# -- the decision's deadline -----------------------------------------------------------------------
def test_checkpoints_inside_the_core_model_stop_an_expired_decision():
    ids = scene_ids()
    from el.landing.core import probs_from_labels

    probs = probs_from_labels(ids, (WW, WW * 144 // 256), labels=UAVID)
    clock = FakeClock()
    deadline = dl.Deadline(clock, 1.0)
    run_core(probs, (256, 144), CoreConfig(working_width=WW), labels=UAVID)  # no active deadline: no-op checkpoints
    clock.t = 5.0
    with dl.active(deadline), pytest.raises(BudgetExceeded, match="during candidates"):
        run_core(probs, (256, 144), CoreConfig(working_width=WW), labels=UAVID)
    cancelled = dl.Deadline(clock, None)
    cancelled.cancelled.set()
    with dl.active(cancelled), pytest.raises(BudgetExceeded):
        dl.checkpoint("anything")


def test_the_hard_stop_returns_the_default_action_while_a_stage_still_runs():
    """A segmenter stuck for 3 s in one call (no checkpoint inside): with a 0.2 s budget the caller gets the
    default action ("timeout") long before the call ends; the stopped worker then ends at its next checkpoint."""
    class Stuck(OracleSegmenter):
        def predict_frame(self, rgb):
            time.sleep(3.0)
            return super().predict_frame(rgb)

    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", time_budget_s=0.2)
    t0 = time.perf_counter()
    d = EmergencyLanding(cfg, segmenter=Stuck(WW)).decide(scene_image(scene_ids()))
    returned = time.perf_counter() - t0
    assert (d.action, d.reason) == ("default", "timeout") and returned < 2.0
    assert d.input["width"] == 256 and d.default_area.y > 72  # the frame's own default area
    for t in threading.enumerate():
        if t.name == "uav-el-decision":
            t.join(10)
    # without the hard stop (or with an injected clock), the cooperative checks alone: after the call
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", time_budget_s=0.2, hard_stop=False)
    assert cfg.to_dict()["hard_stop"] is False and "hard_stop" not in PipelineConfig().to_dict()


def test_decisions_within_the_budget_are_those_without_one():
    image = scene_image(scene_ids())
    base = dict(core=CoreConfig(working_width=WW), monitor="lhd+ch:tau=0.25", evaluate_all=True)
    a = EmergencyLanding(PipelineConfig(**base, time_budget_s=100.0), segmenter=OracleSegmenter(WW)).decide(image)
    b = EmergencyLanding(PipelineConfig(**base, time_budget_s=None), segmenter=OracleSegmenter(WW)).decide(image)
    assert a.action == b.action == "land" and a.selected == b.selected
    assert [c.monitor.reason for c in a.candidates] == [c.monitor.reason for c in b.candidates]


# -- campaigns: shard names, meta, configuration faults, index repair ------------------------------
def test_shard_names_cannot_collide_and_stay_readable():
    a, b = readouts.shard_name("none", 3, "seq00/a b"), readouts.shard_name("none", 3, "seq00/a_b")
    assert a != b and a.startswith("none-s3__seq00_a_b-") and len(a.rsplit("-", 1)[1]) == 16
    assert readouts.shard_name("fog", 3, "seq00/a_b") != b
    assert readouts.shard_name("none", 3, "seq00/" + "x" * 500).__len__() < 140


def test_fault_classification():
    assert faults.is_data_fault("DataError: x.png: not a readable image")
    assert faults.is_data_fault("LabelColourError: y.png: unknown colours")
    assert not faults.is_data_fault("ValueError: frame: non-finite")
    lines = ["none-s3__a-0: DataError: bad", "none-s3__b-1: RuntimeError: broken"]
    assert faults.config_faults(lines) == ["none-s3__b-1: RuntimeError: broken"]
    assert "1 task(s) faulted for a configuration reason" in faults.config_fault_line(lines)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    from assurance.dataio.uavid import write_sample
    from el.classes.labels import ids_to_colors

    root = tmp_path_factory.mktemp("bounds_run")
    for i, frame in enumerate(("a b", "a_b", "000002")):
        ids = scene_ids(seed=i)
        write_sample(root / "data", "seq00", frame, ids_to_colors(ids), ids, labels=UAVID)
    (root / "data" / "seq00" / "meta").mkdir()
    (root / "data" / "seq00" / "meta" / "000002.json").write_text(json.dumps({"note": "meta"}))
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), core=CoreConfig(working_width=WW))
    summary = run_campaign(root / "data", root / "run", config, segmenter=OracleSegmenter(WW),
                           execution=Execution(progress=False))
    return {"root": root, "config": config, "summary": summary}


def test_frames_whose_names_differ_only_in_punctuation_are_both_evaluated(small_run):
    s = small_run["summary"]
    assert s["done"] == 3 and s["faults"] == [] and s["config_faults"] == []
    keys = set(readouts.load_table(small_run["root"] / "run", "images")["key"])
    assert keys == {"seq00/a b", "seq00/a_b", "seq00/000002"}
    assert len(readouts.shard_dirs(small_run["root"] / "run")) == 3


def test_meta_files_are_in_the_data_hash(small_run, tmp_path):
    root = small_run["root"]
    data, run = tmp_path / "data", tmp_path / "run"
    shutil.copytree(root / "data", data)
    shutil.copytree(root / "run", run)
    man = json.loads((run / "manifest.json").read_text())
    man["data"]["path"] = str(data.resolve())
    (run / "manifest.json").write_text(json.dumps(man))
    seg = OracleSegmenter(WW)
    assert run_campaign(data, run, small_run["config"], segmenter=seg,
                        execution=Execution(progress=False))["skipped"] == 3  # control
    (data / "seq00" / "meta" / "000002.json").write_text(json.dumps({"note": "edited"}))
    with pytest.raises(readouts.RunError, match="differs in 'data'"):
        run_campaign(data, run, small_run["config"], segmenter=seg, execution=Execution(progress=False))


def test_a_corrupt_index_is_repaired_by_the_advised_rerun(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run["root"] / "run", run)
    (run / readouts.INDEX).write_text("{ not json")
    with pytest.raises(readouts.DamagedRunError, match="re-run the same `uav-el campaign` command"):
        verify_run(run)
    s = run_campaign(small_run["root"] / "data", run, small_run["config"],
                     segmenter=OracleSegmenter(WW), execution=Execution(progress=False))
    assert s["skipped"] == 3 and len(s["repaired"]) == 1 and "set aside as damaged/shards.json.0" in s["repaired"][0]
    check = verify_run(run)
    assert check.ok and check.shards == 3 and (run / "damaged" / "shards.json.0").is_file()
    assert set(readouts.read_index(run)) == {p.name for p in readouts.shard_dirs(run)}


def test_a_run_of_the_old_format_reads_but_is_not_resumed(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run["root"] / "run", run)
    man = json.loads((run / "manifest.json").read_text())
    man["format"] = "uav-el-readouts/1"
    (run / "manifest.json").write_text(json.dumps(man))
    assert len(readouts.load_table(run, "images")) == 3 and verify_run(run).ok
    with pytest.raises(readouts.RunError, match="readouts format uav-el-readouts/1 .*new --out folder"):
        run_campaign(small_run["root"] / "data", run, small_run["config"],
                     segmenter=OracleSegmenter(WW), execution=Execution(progress=False))


def test_a_campaign_whose_tasks_fault_for_a_configuration_reason_exits_2(small_run, tmp_path, capsys):
    from assurance.fault_injection.case import save_tiny_weights

    w = save_tiny_weights(tmp_path / "nan.pt", nan=True)
    code = main(["campaign", "--data", str(small_run["root"] / "data"), "--out", str(tmp_path / "run"),
                 "--weights", str(w), "--perturbations", "none", "--monitors", "lhd", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "3 task(s) faulted for a configuration reason" in err and err.count("\n") == 1
    assert len(readouts.shard_dirs(tmp_path / "run")) == 3  # the faults are recorded, nothing lost


@pytest.mark.slow
def test_workers_die_with_a_sigkilled_campaign(tmp_path):
    from assurance.fault_injection.bounds import killed_campaign_survivors
    from assurance.fault_injection.table import build_workspace

    if not hasattr(__import__("os"), "sched_getaffinity"):
        pytest.skip("Linux only")
    ws = build_workspace(tmp_path, main=main)
    assert killed_campaign_survivors(ws, ws / "killed") == []


def test_a_campaign_records_the_exif_orientation_it_applied(tmp_path):
    from PIL import Image

    from assurance.dataio.uavid import write_labels
    from el.classes.labels import ids_to_colors

    ids = scene_ids()
    seq = tmp_path / "data" / "seq00"
    (seq / "Images").mkdir(parents=True)
    exif = Image.Exif()
    exif[0x0112] = 3  # stored upside down
    Image.fromarray(ids_to_colors(ids)[::-1, ::-1]).save(seq / "Images" / "000000.jpg", quality=98,
                                                       exif=exif.tobytes())
    write_labels(seq / "Labels" / "000000.png", ids, labels=UAVID)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), core=CoreConfig(working_width=WW))
    s = run_campaign(tmp_path / "data", tmp_path / "run", config, segmenter=OracleSegmenter(WW),
                     execution=Execution(progress=False))
    assert s["faults"] == []
    images = readouts.load_table(tmp_path / "run", "images")
    assert images["exif_orientation"].tolist() == [3] and images["candidates"].iloc[0] > 0
