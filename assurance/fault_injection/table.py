"""Fault injection: the hostile-user cases (H1-H8) and a few bad inputs, replayed through the real command line.

``build_workspace`` makes a scratch workspace (two 320x180 synthetic scenes, a tiny CNN's weights, a 2-image
campaign run); ``run_cases`` injects each fault into a copy of what it needs and runs ``uav-el`` in-process
(``assurance.cli.main``, passed in by the caller: the command line imports this module through ``uav-el
fault-table``, so importing it back would be a cycle), recording the exit code and the first line that says
what happened. A case passes when the exit code is the expected one, the expected words are in the output
and no traceback was printed. ``uav-el fault-table`` writes the table (CSV and Markdown); the evidence
report shows it as an appendix when ``faults.csv`` lies next to it.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import shutil
from collections.abc import Sequence
from pathlib import Path

from assurance import requirements as rq
from assurance.campaign.integrity import code_sha256, verify_run
from assurance.dataio.uavid import read_image, write_image
from assurance.fault_injection.applicant import APPLICANT_CASES
from assurance.fault_injection.bounds import BOUNDS_CASES
from assurance.fault_injection.case import Case, CliMain, run_cli, save_tiny_weights, use_cli, write_small_frame_system
from assurance.fault_injection.case import campaign_argv as _campaign
from assurance.fault_injection.case import copy_run as _copy_run
from assurance.fault_injection.case import first_image as _image
from assurance.fault_injection.flightlog_cases import FLIGHTLOG_CASES
from assurance.fault_injection.gate import GATE_CASES
from assurance.fault_injection.signing import SIGNING_CASES
from assurance.files import atomic_write_bytes

COLUMNS = ("case", "injected", "command", "expected", "observed", "outcome", "result")
CSV_NAME, MD_NAME = "faults.csv", "faults.md"
MCD_SPEC = "lhd+ch+mcd:tau=0.25,n=1000,rho=0.5"

# ------------------------------------------------------------------------------------------------
# Workspace
# ------------------------------------------------------------------------------------------------
def build_workspace(root: str | Path, *, main: CliMain) -> Path:
    """Two 320x180 synthetic test scenes, tiny weights, a finished 2-image campaign run and ``WS/uav-el.toml`` under
    ``root``: the embedded default but for a declared domain that admits the small frames (the default declares only
    4K frames), so that the cases, run in ``WS`` (``run_case``), exercise the decisions, not the frame-size check."""
    ws = Path(root).resolve()
    write_small_frame_system(ws)
    steps = (["synth", "--out", ws / "data", "--split", "test", "--scenes", "2", "--size", "320x180",
              "--no-progress"],)
    for argv in steps:
        code, _, err = run_cli(main, argv)
        if code:
            raise RuntimeError(f"fault-table workspace: uav-el {argv[0]} exited {code}: {err.strip()}")
    save_tiny_weights(ws / "tiny.pt")
    with contextlib.chdir(ws):
        code, _, err = run_cli(main, _campaign(ws, ws / "run"))
    if code:
        raise RuntimeError(f"fault-table workspace: uav-el campaign exited {code}: {err.strip()}")
    return ws


def _copy_weights(ws: Path, name: str) -> Path:
    dst = ws / name
    shutil.copy(ws / "tiny.pt", dst)
    shutil.copy(ws / "tiny.json", dst.with_suffix(".json"))
    return dst


# ------------------------------------------------------------------------------------------------
# The cases
# ------------------------------------------------------------------------------------------------
def _run_system_sha(run: Path) -> str | None:
    return (json.loads((run / "manifest.json").read_text()).get("system") or {}).get("sha256")


def _forged_requirements(ws: Path) -> list[str]:
    """Results bound to this run, code and registry, with every state set to "verified" by hand."""
    reg = rq.load_registry(None)
    doc = {"format": rq.RESULTS_FORMAT,
           "context": {"run": str(ws / "run"), "run_digest": verify_run(ws / "run").digest,
                       "code_sha256": code_sha256(), "system_sha256": _run_system_sha(ws / "run")},
           "registry": {"sha256": reg.sha256, "parameters_sha256": reg.parameters_sha256},
           "requirements": {r.id: {"state": rq.VERIFIED, "reason": "forged", "tests": []} for r in reg}}
    forged = ws / "forged.json"
    forged.write_text(json.dumps(doc), encoding="utf-8")
    return ["evidence", "--run", ws / "run", "--out", ws / "rep-forged", "--no-pdf", "--boot", "20",
            "--requirements", forged, "--strict"]


def _altered_shard(ws: Path) -> list[str]:
    import pandas as pd

    run, shards = _copy_run(ws, "run-altered")
    path = shards[0] / "candidates.parquet"
    cands = pd.read_parquet(path)
    cands["true_unsafe"] = ~cands["true_unsafe"].astype(bool)
    cands.to_parquet(path, index=False)
    return ["evidence", "--run", run, "--out", ws / "rep-altered", "--no-pdf", "--boot", "20"]


def _truncated_shard(ws: Path) -> list[str]:
    run, shards = _copy_run(ws, "run-truncated")
    f = shards[0] / "images.parquet"
    f.write_bytes(f.read_bytes()[:100])
    return _campaign(ws, run)


def _deleted_shard(ws: Path) -> list[str]:
    run, shards = _copy_run(ws, "run-deleted")
    shutil.rmtree(shards[-1])
    return ["table", run, "--boot", "20"]


def _existing_file(ws: Path) -> list[str]:
    f = ws / "file.txt"
    f.write_text("x")
    return _campaign(ws, f)


def _altered_weights(ws: Path) -> list[str]:
    w = _copy_weights(ws, "altered.pt")
    data = bytearray(w.read_bytes())
    data[len(data) // 2] ^= 0xFF
    w.write_bytes(bytes(data))
    return ["land", _image(ws), "--weights", w]


def _pickled_weights(ws: Path) -> list[str]:
    """A pickle that would run code when loaded (its card records its hash, so only the format refuses it)."""
    import hashlib
    import os

    import torch

    class Evil:
        def __reduce__(self):
            return (os.system, ("echo pwned",))

    buf = io.BytesIO()
    torch.save({"x": Evil()}, buf)
    w = _copy_weights(ws, "pickled.pt")
    w.write_bytes(buf.getvalue())
    card = json.loads(w.with_suffix(".json").read_text())
    card["weights_sha256"] = hashlib.sha256(buf.getvalue()).hexdigest()
    w.with_suffix(".json").write_text(json.dumps(card))
    return ["land", _image(ws), "--weights", w]


def _unreadable_image(ws: Path) -> list[str]:
    bad = ws / "garbage.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n not an image")
    return ["land", bad, "--weights", ws / "tiny.pt"]


def _wrong_shape_labels(ws: Path) -> list[str]:
    labels = sorted((ws / "data").glob("*/Labels/*.png"))[0]

    small = ws / "labels-small.png"
    write_image(small, read_image(labels)[:90, :160])
    return ["land", "--labels", small, "--image", _image(ws)]


def _nan_model(ws: Path) -> list[str]:  # a rule monitor: the deployed one refuses a network it was not fitted on
    return ["land", _image(ws), "--weights", save_tiny_weights(ws / "nan.pt", nan=True), "--monitor", "lhd"]


CASES: tuple[Case, ...] = (
    Case("H1-forged-requirements", "requirements JSON bound to the run, every state set to 'verified' by hand "
         "(--strict)", _forged_requirements, 1, "gate: FAILED", "gate:"),
    Case("H2-altered-shard", "true_unsafe flipped in one shard's candidates.parquet", _altered_shard, 4,
         "differs from its SHA256SUMS"),
    Case("H3-budget-timeout", f"land --monitor '{MCD_SPEC}' with a 0.05 s budget",
         lambda ws: ["land", _image(ws), "--weights", ws / "tiny.pt", "--monitor", MCD_SPEC, "--budget", "0.05"],
         0, "reason: timeout", "decision:"),
    Case("H4-truncated-shard", "images.parquet of one shard cut to 100 bytes, then the campaign re-run",
         _truncated_shard, 0, "1 already done", "differs from its SHA256SUMS"),
    Case("H5-negative-seed", "campaign --seed -1", lambda ws: _campaign(ws, ws / "run-neg", "--seed", "-1"), 2,
         "seed must be an integer >= 0"),
    Case("H6-deleted-shard", "one shard folder deleted, then table", _deleted_shard, 4, "shard folder missing"),
    Case("H7-overlay-extension", "land --overlay out.xyz",
         lambda ws: ["land", _image(ws), "--weights", ws / "tiny.pt", "--overlay", ws / "out.xyz"], 2,
         "unknown image type"),
    Case("H7-out-is-a-file", "campaign --out EXISTING_FILE", _existing_file, 2, "exists and is not a folder"),
    Case("H8-json-is-a-folder", "land --json DIR",
         lambda ws: ["land", _image(ws), "--weights", ws / "tiny.pt", "--json", ws], 2, "is a folder"),
    Case("H8-altered-weights", "one byte of the weights file flipped", _altered_weights, 2, "SHA-256 mismatch"),
    Case("H8-pickled-weights", "weights file holding a pickle that runs a shell command (card re-hashed)",
         _pickled_weights, 2, "refused: the file holds pickled objects"),
    Case("H9-foreign-network", "land with the deployed monitor and its card on another network's weights",
         lambda ws: ["land", _image(ws), "--weights", ws / "tiny.pt"], 2, "fitted on network"),
    Case("B1-unreadable-image", "land on a file that is not an image", _unreadable_image, 2),
    Case("B2-wrong-shape-labels", "land --labels of another size than --image", _wrong_shape_labels, 2),
    Case("B3-missing-weights", "land --weights NOT_THERE.pt",
         lambda ws: ["land", _image(ws), "--weights", ws / "missing.pt"], 2, "weights file not found"),
    Case("B4-nan-model", "weights whose every parameter is NaN (valid card)", _nan_model, 3,
         "DEFAULT action", "decision:"),
    Case("B5-missing-run", "table on a folder that is not a run",
         lambda ws: ["table", ws / "no-run", "--boot", "20"], 2),
    *BOUNDS_CASES,  # bounded resources, no silent loss
    *SIGNING_CASES,  # forged evidence, the gate's policy
    *GATE_CASES,  # a gate that verifies what it says, models bound to the run
    *APPLICANT_CASES,  # the auditor's trust boundary: supplied templates never execute, read files or contradict
    *FLIGHTLOG_CASES,  # flight logs in service: a breach hidden in the logs, the hash chain, sequence and times
)

QUICK: tuple[str, ...] = ("H2-altered-shard", "H8-pickled-weights", "B1-unreadable-image", "B4-nan-model",
                          "R1-pixel-header", "R4-yaml-alias-bomb", "S1-fabricated-run", "S3-untrusted-key",
                          "G6-edited-manifest", "T3-template-claims-passed", "T29-meta-refresh",
                          "L3-refusal-relabelled")
"""A representative slice for a first look (``uav-el fault-table --quick``, ``make demo``): one or two of the
cheapest cases of each family (hostile inputs, bad inputs, bounded resources, signing, the gate, the auditor's
trust boundary). The report says how many of the cases a table holds; ``make faults`` and CI replay all."""


# ------------------------------------------------------------------------------------------------
# Running and writing
# ------------------------------------------------------------------------------------------------
def _outcome(case: Case, out: str, err: str) -> str:
    lines = [ln.strip() for ln in (err + "\n" + out).splitlines() if ln.strip()]
    if case.pick:
        picked = [ln for ln in lines if case.pick in ln]
        if picked:
            return picked[0]
    err_lines = [ln.strip() for ln in err.splitlines() if ln.strip()]
    return (err_lines or lines or [""])[0]


def run_case(case: Case, ws: Path, *, main: CliMain) -> dict[str, str]:
    """Inject ``case`` into the workspace ``ws`` and replay it through ``main``; the table row."""
    use_cli(main)
    with contextlib.chdir(ws):  # the workspace's system file (build_workspace) is the one found
        argv = [str(a) for a in case.make(ws)]
        code, out, err = run_cli(main, argv)
    text = out + err
    problem = case.check(ws) if case.check is not None else None
    ok = code == case.expected and case.expect_text in text and "Traceback" not in text and problem is None
    command = "uav-el " + " ".join(a.replace(str(ws), "WS") if str(ws) in a else a for a in argv)
    outcome = _outcome(case, out, err).replace(str(ws), "WS") + (f" [{problem}]" if problem else "")
    return {"case": case.id, "injected": case.injected, "command": command, "expected": str(case.expected),
            "observed": str(code), "outcome": outcome, "result": "pass" if ok else "FAIL"}


def run_cases(ws: Path, cases: Sequence[Case] = CASES, *, main: CliMain) -> list[dict[str, str]]:
    """The table rows of ``cases`` replayed through ``main`` in the workspace ``ws``."""
    return [run_case(c, ws, main=main) for c in cases]


def to_csv(rows: Sequence[dict[str, str]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def to_markdown(rows: Sequence[dict[str, str]]) -> str:
    def cell(v: str) -> str:
        return v.replace("|", "\\|").replace("\n", " ")

    head = ("case", "injected", "expected", "observed", "outcome", "result")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cell(r[k]) for k in head) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def read_table(path: str | Path) -> list[dict[str, str]]:
    """The rows of a ``faults.csv`` (raises ValueError when its columns are not the table's)."""
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if tuple(reader.fieldnames or ()) != COLUMNS:
            raise ValueError(f"{path}: not a fault-injection table (columns {reader.fieldnames})")
        return list(reader)


def write_table(rows: Sequence[dict[str, str]], csv_path: str | Path) -> tuple[Path, Path]:
    """Write ``faults.csv`` and ``faults.md`` (beside it) atomically."""
    csv_path = Path(csv_path)
    md_path = csv_path.with_suffix(".md")
    atomic_write_bytes(csv_path, to_csv(rows).encode("utf-8"))
    atomic_write_bytes(md_path, to_markdown(rows).encode("utf-8"))
    return csv_path, md_path
