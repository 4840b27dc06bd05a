"""In-service evidence (issue 53): flight logs written by the flight function (``el.flight.flightlog``) compared with
the
certification run of their system (``uav-el in-service``, ``assurance.inservice``).

The demonstration: a tiny network carrying a fitted frame gate, a campaign on small in-domain test scenes, then
flights logged over other in-domain scenes (no SPI breached) and over shifted ones, fog at severity 5 and night (the
frames at a quarter of their brightness): the frame gate's scores drift (p < 0.01) and named SPIs are breached. A log
of another system is refused in one line, damaged lines are counted, and a large log reads in bounded memory.
"""

from __future__ import annotations

import hashlib
import json
import math
import tracemalloc

import numpy as np
import pytest
from helpers import TINY_ARCH, TappedOracle, write_textured_scenes

from assurance import cli
from assurance.dataio.uavid import read_image
from assurance.inservice import spi
from assurance.inservice.reader import MAX_WINDOWS, LogSummary, Reservoir, read_logs
from assurance.inservice.report import check_attestation
from assurance.perturbations import perturb
from el.base.decision import Candidate, Decision, Disc, MonitorVerdict
from el.base.hashing import sha256_file
from el.flight.flightlog import MAX_RECORD_BYTES, FlightLog, flightlog_schema
from el.geometry.camera import Pose
from el.geometry.config import CoreConfig

W, H, WW = 128, 72, 64
SHA = "7e" * 32
SYSTEM = """[odd]
image_width = [100, 200]
image_height = [50, 100]
aspect = [1.5, 2.0]
[in_service]
max_refusal_rate = 0.3
max_default_rate = 0.8
max_overrun_rate = 0.1
drift_alpha = 0.01
"""
SHIFTS = {
    "in_domain": lambda rgb, i: rgb,
    "fog5": lambda rgb, i: perturb(rgb, "fog", 5, np.random.default_rng(i)),
    "night": lambda rgb, i: (rgb.astype(np.float32) * 0.25).astype(np.uint8),
}


class Minutes:
    """A wall clock one minute apart per reading (the records' time)."""

    def __init__(self) -> None:
        self.t = 1_790_000_000.0

    def __call__(self) -> float:
        self.t += 60.0
        return self.t


@pytest.fixture(scope="module")
def world(tmp_path_factory, one_torch_thread):
    """The certification run (signed, its system file declaring the SPIs) and one flight log per shift."""
    import torch

    from assurance.campaign.run import CampaignConfig, Execution, run_campaign
    from assurance.fitting.frame_gate_fit import GateSettings, fit_gate
    from assurance.system import build as system_build
    from assurance.system import load_system
    from el.classes.labels import UAVID
    from el.flight.pipeline import EmergencyLanding, PipelineConfig
    from el.monitors.frame_gate import load_frame_gate
    from el.segmentation.architectures import build_model
    from el.segmentation.inference import Segmenter

    root = tmp_path_factory.mktemp("in_service")
    train, val = write_textured_scenes(root / "train", range(20)), write_textured_scenes(root / "val", range(40, 46))
    write_textured_scenes(root / "test", range(100, 124))
    write_textured_scenes(root / "service", range(300, 324))  # flown: other scenes of the same domain
    torch.manual_seed(0)
    seg = Segmenter(build_model(TINY_ARCH), working_width=WW, card={"weights_sha256": SHA}, labels=UAVID)
    doc = fit_gate(train, val, seg, settings=GateSettings(kind="mahalanobis", quantile=0.99), val_scenes="0:6",
                   weights={"path": None, "sha256": SHA, "segmenter": "weights"})
    (root / "gate.json").write_text(json.dumps(doc), "utf-8")
    gate = load_frame_gate(root / "gate.json")
    (root / "uav-el.toml").write_text(SYSTEM, "utf-8")
    system = load_system(root / "uav-el.toml")
    odd, tapped = system_build.odd(system), TappedOracle(seg, WW, SHA)
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), core=CoreConfig(working_width=WW),
                            gate={"path": str(root / "gate.json"), "sha256": gate.sha256}, odd=odd.to_dict())
    assert run_campaign(root / "test", root / "run", config, segmenter=tapped,
                        system=system, execution=Execution(progress=False))["faults"] == []
    landing = EmergencyLanding(PipelineConfig(core=config.core, monitor="lhd", gate=str(root / "gate.json"), odd=odd,
                                              time_budget_s=None), segmenter=tapped)
    assert landing.fault is None
    frames = sorted((root / "service" / "seq00").glob("Images/*.png"))
    logs = {}
    for name, shift in SHIFTS.items():
        logs[name] = root / f"{name}.jsonl"
        with FlightLog(logs[name], system_sha256=system.sha256, fsync=False, clock=Minutes()) as log:
            landing.log = log  # the flight function appends each decision (EmergencyLanding(..., log=...))
            for i, path in enumerate(frames):
                landing.decide(shift(read_image(path), i), pose=Pose(height_m=50.0, pitch_deg=45.0))
            assert log.failures == 0, log.last_error
        landing.log = None
    return {"root": root, "run": root / "run", "logs": logs, "system": system, "landing": landing, "seg": tapped}


def _in_service(world, tmp_path, *logs, extra=()):
    out = tmp_path / "out"
    code = cli.main(["in-service", *map(str, logs), "--run", str(world["run"]), "--out", str(out), *extra])
    doc = json.loads((out / "in-service.json").read_text()) if (out / "in-service.json").is_file() else None
    return code, doc, out


def test_logs_over_in_domain_scenes_breach_no_spi(world, tmp_path, capsys):
    code, doc, out = _in_service(world, tmp_path, world["logs"]["in_domain"])
    assert code == 0, capsys.readouterr().err
    assert doc["verdict"] == "no breach" and doc["breaches"] == [] and doc["undermined"] == []
    assert doc["records"] == 24 and doc["damaged"] == 0
    drift = doc["comparison"]["frame_gate"]["drift"]
    assert drift["n_service"] == drift["n_run"] == 24 and drift["p_value"] >= 0.01
    verdicts = {s["name"]: s["verdict"] for s in doc["spis"]}
    assert verdicts["refusal_rate"] == verdicts["frame_gate_drift"] == spi.PASS
    assert verdicts["overrun_rate"] == spi.UNDECIDED  # 0 of 24 cannot show a rate below 10% at 95%
    html = (out / "in-service.html").read_text()
    assert "NO BREACH" in html
    gate_file = sha256_file(world["root"] / "gate.json")  # issue 60: the gate named as the evidence report names it
    assert doc["identity"]["gate_file_sha256"] == gate_file and gate_file in html
    assert doc["comparison"]["frame_gate"]["file_sha256_in_logs"] == [gate_file]
    assert doc["identity"]["gate_sha256"] != gate_file and doc["identity"]["gate_sha256"] in html  # labelled apart


@pytest.mark.parametrize("shift", ["fog5", "night"])
def test_logs_over_shifted_scenes_show_the_drift_and_a_named_breach(shift, world, tmp_path, capsys):
    code, doc, out = _in_service(world, tmp_path, world["logs"][shift])
    printed = capsys.readouterr().out
    assert code == 1
    assert doc["comparison"]["frame_gate"]["drift"]["p_value"] < 0.01
    assert doc["verdict"] == "breach" and "frame_gate_drift" in doc["breaches"]
    undermined = {c["node"]: c for c in doc["undermined"]}
    assert {"G-EL-R09", "G-EL-R10"} <= set(undermined)  # the claims named, with their requirement's title
    assert undermined["G-EL-R10"]["requirement"] == "EL-R10" and undermined["G-EL-R10"]["title"]
    assert "undermined: G-EL-R09" in printed and "breach" in printed
    predicate, problems = check_attestation(out, _trusted())
    assert problems == [] and predicate["verdict"] == "breach" and predicate["network_sha256"] == SHA
    if shift == "night":  # every dark frame refused by the gate: the refusal and default SPIs are breached too
        assert {"refusal_rate", "default_rate"} <= set(doc["breaches"])


def _trusted():
    from assurance.attest.keys import load_signing_key

    key = load_signing_key()
    return {key.keyid: key.public}


def test_an_altered_report_no_longer_verifies(world, tmp_path):
    _, _, out = _in_service(world, tmp_path, world["logs"]["night"])
    doc = json.loads((out / "in-service.json").read_text())
    doc["breaches"] = []
    (out / "in-service.json").write_text(json.dumps(doc))
    _, problems = check_attestation(out, _trusted())
    assert any("in-service.json: altered after signing" in p for p in problems)


def test_a_log_of_another_system_is_refused_in_one_line(world, tmp_path, capsys):
    other = tmp_path / "other.jsonl"
    with FlightLog(other, network_sha256="ab" * 32, system_sha256=world["system"].sha256, fsync=False) as log:
        log.write(world["landing"].decide(read_image(next((world["root"] / "test").rglob("*.png")))))
    code, doc, _ = _in_service(world, tmp_path, world["logs"]["in_domain"], other)
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert code == 2 and doc is None
    assert len(err) == 1 and f"{other}:1: a decision of another system (network sha256 abababababab" in err[0]


def chained(lines: list[bytes], prev: str | None) -> list[bytes]:
    """Records re-chained after ``prev`` (the SHA-256 of the line before them), as a writer reopening the log after
    a crash writes them (``el.flight.flightlog.FlightLog`` chains to the damaged last line)."""
    out = []
    for line in lines:
        rec = json.loads(line)
        rec["prev_sha256"] = prev
        out.append((json.dumps(rec, separators=(",", ":"), ensure_ascii=False) + "\n").encode())
        prev = hashlib.sha256(out[-1]).hexdigest()
    return out


def test_damaged_lines_are_counted_and_named(world, tmp_path, capsys):
    log = tmp_path / "damaged.jsonl"
    good = world["logs"]["in_domain"].read_bytes().splitlines(keepends=True)
    bad = [b'{"format": "uav-el-flight-log/2", "seq": 3, "syst\n', b"\xff\xfe not text\n",
           b'{"format": "uav-el-flight-log/9"}\n', b'{"pad": "' + b"x" * (MAX_RECORD_BYTES + 10) + b'"}\n',
           b"[1, 2]\n"]
    rest = chained(good[10:], hashlib.sha256(bad[-1]).hexdigest())  # the writer reopened after the damage
    log.write_bytes(b"".join(good[:10] + bad + rest) + b'{"format": "uav-el-flight-log/2", "se')  # a crash
    code, doc, _ = _in_service(world, tmp_path, log)
    assert code == 0, capsys.readouterr().err
    assert doc["records"] == 24 and doc["damaged"] == 6 and doc["logs"][0]["damaged"] == 6
    named = doc["damaged_lines"]
    assert named[0].startswith(f"{log}:11: not a JSON record") and f"{log}:12: not UTF-8 text" in named[1]
    assert "format 'uav-el-flight-log/9'" in named[2] and f"longer than {MAX_RECORD_BYTES} bytes" in named[3]
    assert named[-1].startswith(f"{log}:30: ")


def test_a_large_log_reads_in_bounded_memory(world, tmp_path):
    """A 50 MB log (12 000 records of 4 kB) read by the streaming reader: its peak allocation stays a small fraction
    of the file, as it would for 1 GB (nothing is kept per record but counters and fixed-size samples)."""
    record = json.loads(world["logs"]["in_domain"].read_text().splitlines()[0])
    record["pad"] = "x" * 3000  # extra fields are allowed: a record of ~4 kB
    size = len(json.dumps(record, separators=(",", ":"))) + 1
    big, n = tmp_path / "big.jsonl", (50 << 20) // size
    prev = None
    with open(big, "wb") as f:  # one chain of n records, a second apart
        for seq in range(n):
            record.update(seq=seq, prev_sha256=prev, unix_s=record["unix_s"] + 1.0)
            line = (json.dumps(record, separators=(",", ":")) + "\n").encode()
            prev = hashlib.sha256(line).hexdigest()
            f.write(line)
    assert big.stat().st_size > 48 << 20
    summary = LogSummary(gate_scores=Reservoir(2000), candidate_scores=Reservoir(2000), times=Reservoir(2000))
    tracemalloc.start()
    try:
        read_logs([big], summary=summary)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert summary.records == n and summary.damaged == 0
    assert peak < 8 << 20, f"peak {peak / 2**20:.1f} MiB reading a {big.stat().st_size / 2**20:.0f} MiB log"
    assert len(summary.gate_scores.values) == 2000 and summary.gate_scores.seen == n
    assert MAX_WINDOWS <= len(summary.timeline.windows) <= 2 * MAX_WINDOWS


def test_a_reservoir_is_bounded_uniform_and_deterministic():
    a, b = Reservoir(100, seed=1), Reservoir(100, seed=1)
    for x in range(10_000):
        a.add(float(x))
        b.add(float(x))
    assert len(a.values) == 100 and a.values == b.values and a.seen == 10_000
    assert 3000 < np.mean(a.values) < 7000  # drawn from the whole stream, not its first 100


def _decision(judged: int, reason: str = "all_rejected") -> Decision:
    cands = [Candidate(k, 10.0 + k, 20.0, 5.0, 0.1, 0.1, 0.0, MonitorVerdict("lhd", False, "hazard", 0.01, 0.7, 0.5))
             for k in range(judged)]
    return Decision(action="default", reason=reason, selected=None, candidates=cands,
                    default_area=Disc(64.0, 60.0, 8.0, "nearest_ground"), timings={"total_s": 0.2, "read_s": math.nan},
                    input={"width": W, "height": H, "sha256": "0" * 64,
                           "pose": {"height_m": 50.0, "pitch_deg": 45.0, "source": "frame"}},
                    config={"monitor": "lhd", "time_budget_s": 0.1})


def test_a_record_is_bounded_and_valid_against_its_schema(tmp_path):
    import jsonschema

    path = tmp_path / "log.jsonl"
    with FlightLog(path, network_sha256=SHA, system_sha256=None, fsync=True) as log:
        assert log.write(_decision(3)) and log.write(_decision(5000, "fault: monitoring: ValueError: " + "x" * 999))
    lines = path.read_bytes().splitlines(keepends=True)
    assert all(len(line) <= MAX_RECORD_BYTES for line in lines)
    validator = jsonschema.Draft202012Validator(flightlog_schema())
    for line in lines:
        validator.validate(json.loads(line))
    first, second = (json.loads(line) for line in lines)
    assert first["deadline"] == {"budget_s": 0.1, "total_s": 0.2, "overrun": True}
    assert first["domain"]["verdict"] == "not_declared" and first["timings"] == {"read_s": None, "total_s": 0.2}
    assert second["candidates"]["count"] == 5000 and second["candidates"]["dropped"] == 5000 - 64
    assert len(second["reason"]) == 240


def test_a_write_that_fails_never_raises_and_a_crash_leaves_one_damaged_line(tmp_path):
    handle = open(tmp_path / "closed.jsonl", "w")  # noqa: SIM115
    log = FlightLog(handle)
    handle.close()
    assert log.write(_decision(1)) is False and log.failures == 1 and "closed" in log.last_error
    assert FlightLog(tmp_path / "no" / "such" / "folder.jsonl").write(_decision(1)) is False
    path = tmp_path / "crashed.jsonl"
    path.write_bytes(b'{"format": "uav-el-flight-log/1", "se')  # a record cut by a crash
    with FlightLog(path, network_sha256=SHA, fsync=False) as log:
        assert log.write(_decision(1))
    summary = read_logs([path])
    assert summary.records == 1 and summary.damaged == 1


def test_an_spi_is_undecided_on_too_few_decisions():
    comparison = {"frame_gate": {"refusal": {"service": {"k": 1, "n": 5}, "run": {"k": 0, "n": 24}},
                                 "drift": {"p_value": None, "n_service": 5, "n_run": 24, "why_not": "few"}},
                  "default": {"service": {"k": 0, "n": 5}, "run": {"k": 0, "n": 24}},
                  "overrun": {"service": {"k": 5, "n": 5}, "run": {"k": 0, "n": 24}},
                  "monitor": {"drift": {"p_value": 0.5, "statistic": 0.1, "n_service": 50, "n_run": 50,
                                        "median_service": 0.1, "median_run": 0.1}}}
    results = {r.name: r for r in spi.judge(comparison, spi.settings_of({"max_refusal_rate": 0.3,
                                                                         "max_overrun_rate": 0.1}))}
    assert results["refusal_rate"].verdict == spi.UNDECIDED  # 1 of 5: neither shown above nor below 0.3
    assert results["overrun_rate"].verdict == spi.BREACH  # 5 of 5: shown above 0.1 at any size
    assert results["default_rate"].verdict == spi.NOT_DECLARED
    assert results["frame_gate_drift"].verdict == spi.UNDECIDED and results["monitor_score_drift"].verdict == spi.PASS


def test_the_evidence_report_shows_the_in_service_section(world, tmp_path):
    from assurance.evidence.report import generate

    _, _, service = _in_service(world, tmp_path, world["logs"]["night"])
    common = {"pdf": False, "n_boot": 20, "system": world["system"], "trusted": _trusted()}
    generate(world["run"], tmp_path / "with", in_service=service, **common)
    html = (tmp_path / "with" / "evidence.html").read_text()
    section = html[html.index('<section id="in-service">'):]
    section = section[:section.index("</section>")]
    assert "BREACH" in section and "the statement verifies" in section
    assert "G-EL-R09" in section and "frame gate refuses at most 0.3" in section
    assert f"SHA-256 {sha256_file(world['root'] / 'gate.json')[:16]}" in html  # the gate, as in-service names it
    generate(world["run"], tmp_path / "without", **common)
    assert 'id="in-service"' not in (tmp_path / "without" / "evidence.html").read_text()


def test_an_unsigned_run_or_another_configuration_is_refused(world, tmp_path, capsys):
    import shutil

    unsigned = tmp_path / "unsigned"
    shutil.copytree(world["run"], unsigned)
    (unsigned / "campaign.dsse.json").unlink()
    code = cli.main(["in-service", str(world["logs"]["in_domain"]), "--run", str(unsigned), "--out",
                     str(tmp_path / "a")])
    assert code == 4 and "campaign.dsse.json: missing" in capsys.readouterr().err
    other = tmp_path / "other_monitor.jsonl"  # the run assessed lhd only
    edited = world["logs"]["in_domain"].read_bytes().replace(b'"monitor":"lhd"', b'"monitor":"lhd+ch:tau=0.25"')
    other.write_bytes(b"".join(chained(edited.splitlines(keepends=True), None)))  # a chain as a writer would make
    code, doc, _ = _in_service(world, tmp_path, other)
    assert code == 2 and doc is None and "which the run did not assess" in capsys.readouterr().err


def test_the_system_file_declares_the_spis_within_their_ranges(tmp_path):
    from assurance.system import SystemFileError, load_system
    from assurance.system import build as system_build

    good = tmp_path / "good.toml"
    good.write_text("[in_service]\nmax_default_rate = 0.4\n")
    assert system_build.in_service(load_system(good)) == {"max_default_rate": 0.4}
    bad = tmp_path / "bad.toml"
    bad.write_text("[in_service]\nmax_refusal_rate = 2\n")
    with pytest.raises(SystemFileError, match="in_service.max_refusal_rate"):
        load_system(bad)


def test_every_nth_frame_is_kept_as_a_sample_and_none_by_default(tmp_path):
    frame = np.zeros((H, W, 3), np.uint8)
    with FlightLog(tmp_path / "a.jsonl", network_sha256=SHA, fsync=False, sample_every=2,
                   sample_dir=tmp_path / "frames") as log:
        for _ in range(3):
            assert log.write(_decision(1), frame=frame)
    records = [json.loads(line) for line in (tmp_path / "a.jsonl").read_text().splitlines()]
    assert [("frame_sample" in r) for r in records] == [True, False, True]
    assert (tmp_path / "frames" / records[0]["frame_sample"]).is_file()
    with FlightLog(tmp_path / "b.jsonl", network_sha256=SHA, fsync=False) as log:
        assert log.write(_decision(1), frame=frame)
    assert "frame_sample" not in (tmp_path / "b.jsonl").read_text()
