"""Fault-injection cases of the auditor's trust boundary beyond the templates' contents (rows ``T5``..``T17``,
``T21`` and ``T30``..``T39``): every file an applicant supplies is read bounded, and what it says is checked before
any work starts.

A FIFO or ``/dev/zero`` given as a label set, waivers or targets; a 200 MB poses sidecar; a system file nested
60 000 deep or holding a NaN target; a signing key others can read; a report written inside a run; a waiver
expiring at version 999; a manifest naming tasks the run has no readouts of (re-signed, as the applicant can);
a frame gate or calibration card re-hashed at threshold 1e300; a report template that is a FIFO. Each case returns
the ``uav-el`` command that must refuse it, with one line naming the file and the problem.

Issue 50 (``T30``..``T39``), one reader for every applicant file: a template that is a symbolic link out of its
folder; a manifest (re-signed) naming ``/proc/self/pagemap`` or a FIFO as a model file; a scene ``meta/*.json``
that is a FIFO or a link to ``/dev/zero`` (data folders are not signed); a shard table of 200 000 rows, re-sealed
and re-signed; ``python -m assurance`` run from a folder holding a ``jsonschema.py``; braces in a camera's name; a
waiver dated 2026-02-30; a label set whose hierarchy file is a link out of its folder.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from assurance.attest.keys import create_key, load_signing_key
from assurance.campaign.attestation import sign_run
from assurance.fault_injection.case import Case, campaign_argv, copy_run, first_image, reseal_shard
from el.base.records import body_sha256
from el.classes.labels import PRESET_DIR
from el.flight.pipeline import DEPLOYED_CALIBRATION, DEPLOYED_GATE

SMALL_FRAMES = '[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n'  # the workspace's 320x180 scenes


def _system(ws: Path, name: str, body: str) -> Path:
    """``WS/NAME.toml``: the embedded default with the workspace's small frames, and ``body``."""
    path = ws / f"{name}.toml"
    path.write_text(f'format = "uav-el-system/1"\n{SMALL_FRAMES}{body}', encoding="utf-8")
    return path


def _fifo(ws: Path, name: str) -> Path:
    path = ws / name
    if not path.exists():
        os.mkfifo(path)
    return path


def _evidence(ws: Path, name: str, *extra: object, run: Path | None = None) -> list[str]:
    return ["evidence", "--run", str(run or ws / "run"), "--out", str(ws / f"rep-{name}"), "--no-pdf", "--boot", "20",
            *map(str, extra)]


def _land(ws: Path, system: Path) -> list[str]:
    return ["land", str(first_image(ws)), "--weights", str(ws / "tiny.pt"), "--monitor", "lhd", "--system",
            str(system)]


def _fifo_labels(ws: Path) -> list[str]:
    """A system file whose label set is a FIFO: read plainly, the command waits for a writer for ever."""
    return _land(ws, _system(ws, "sys-fifo-labels", f'[labels]\nfile = "{_fifo(ws, "labels-fifo.yaml")}"\n'))


def _zero_labels(ws: Path) -> list[str]:
    """A label set linked to /dev/zero: read plainly, it grew to 6.5 GB before a MemoryError."""
    link = ws / "labels-zero.yaml"
    if not link.is_symlink():
        link.symlink_to("/dev/zero")
    return _land(ws, _system(ws, "sys-zero-labels", f'[labels]\nfile = "{link}"\n'))


def _huge_poses(ws: Path) -> list[str]:
    """A copy of the data with a 200 MB poses sidecar (sparse), flown under the sidecar pose policy."""
    import shutil

    data = ws / "data-poses"
    if not data.exists():
        shutil.copytree(ws / "data", data)
    seq = sorted(p for p in data.iterdir() if p.is_dir())[0]
    with open(seq / "poses.csv", "wb") as f:
        f.truncate(200 << 20)  # it took 3.5 GB to read
    system = _system(ws, "sys-poses", '[camera]\nposes = "sidecar"\n')
    return [*campaign_argv(ws, ws / "run-poses", data=data), "--system", str(system)]


def _deep_toml(ws: Path) -> list[str]:
    """A system file whose value nests 60 000 brackets deep (it was exit 70, a RecursionError)."""
    path = _system(ws, "sys-deep", "[system]\nname = " + "[" * 60_000 + "]" * 60_000 + "\n")
    return _land(ws, path)


def _nan_target(ws: Path) -> list[str]:
    """A system file whose unsafe-landing bound is NaN (refused only after the campaign ran and signed)."""
    system = _system(ws, "sys-nan", "[targets]\nunsafe_landing_bound = nan\n")
    return [*campaign_argv(ws, ws / "run-nan"), "--system", str(system)]


def _readable_key(ws: Path) -> list[str]:
    """A signing key of mode 0644 (ssh refuses such a key)."""
    key = ws / "readable-key.pem"
    if not key.exists():
        create_key(key)
    key.chmod(0o644)
    return [*campaign_argv(ws, ws / "run-key"), "--signing-key", str(key)]


def _out_inside_run(ws: Path) -> list[str]:
    """The report written into a copy of the run's shards folder (it added a shard the run does not know)."""
    run, _ = copy_run(ws, "run-out-inside")
    return ["evidence", "--run", str(run), "--out", str(run / "shards" / "report"), "--no-pdf", "--boot", "20"]


def _version_waiver(ws: Path) -> list[str]:
    """A well-formed waiver by a declared owner expiring at version 999.0.0 (the same one dated 2999 is refused)."""
    path = ws / "waiver-999.yaml"
    path.write_text("waivers:\n  - id: EL-R10\n    reason: later\n    tracked_by: none\n"
                    "    owner: segmentation maintainers\n    expires: 999.0.0\n", encoding="utf-8")
    return _evidence(ws, "version-waiver", "--waivers", path)


def _missing_tasks(ws: Path) -> list[str]:
    """A copy of the run whose manifest names a task outside the data, re-signed with the applicant's key."""
    run, _ = copy_run(ws, "run-missing-tasks")
    man = json.loads((run / "manifest.json").read_text(encoding="utf-8"))
    man["shard_order"] = [*man["shard_order"], "none-s3__seq00_999999-0000000000000000"]
    (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True), encoding="utf-8")
    sign_run(run, load_signing_key())
    return _evidence(ws, "missing-tasks", run=run)


def _resealed(src: Path, dst: Path, **body: object) -> Path:
    doc = json.loads(src.read_text(encoding="utf-8"))
    doc["body"].update(body)
    doc["sha256"] = body_sha256(doc["body"])
    dst.write_text(json.dumps(doc), encoding="utf-8")
    return dst


def _gate_1e300(ws: Path) -> list[str]:
    """The shipped frame gate re-hashed at threshold 1e300 (it passes every frame), named by a system file."""
    gate = _resealed(Path(DEPLOYED_GATE), ws / "gate-1e300.json", threshold=1e300)
    return _land(ws, _system(ws, "sys-gate", f'[monitor]\ngate = "{gate.name}"\n'))


def _card_1e300(ws: Path) -> list[str]:
    """The shipped calibration card re-hashed at threshold 1e300 (it accepts every candidate)."""
    monitor = json.loads(Path(DEPLOYED_CALIBRATION).read_text())["body"]["monitor"]
    card = _resealed(Path(DEPLOYED_CALIBRATION), ws / "card-1e300.json", threshold=1e300,
                     spec=f"{monitor},threshold=1e+300")
    return ["land", str(first_image(ws)), "--system", str(_system(ws, "sys-card", f'[monitor]\ncalibration = '
                                                                              f'"{card.name}"\n'))]


def _fifo_template(ws: Path) -> list[str]:
    """A template folder whose ``auditor_issre.html.j2`` is a FIFO: Jinja's own loader skipped it for the packaged
    one (or, swapped in after its check, waited on it for ever); the bounded reader refuses it by name."""
    folder = ws / "templates-fifo"
    folder.mkdir(exist_ok=True)
    _fifo(folder, "auditor_issre.html.j2")
    return _evidence(ws, "fifo-template", "--templates", folder)


def _resigned_manifest(ws: Path, name: str, edit: Callable[[dict[str, Any]], None]) -> Path:
    """A copy of the run whose manifest ``edit`` changed, re-signed with the applicant's key (as T15)."""
    run, _ = copy_run(ws, name)
    man = json.loads((run / "manifest.json").read_text(encoding="utf-8"))
    edit(man)
    (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True), encoding="utf-8")
    sign_run(run, load_signing_key())
    return run


def _template_link_outside(ws: Path) -> list[str]:
    """A template folder whose ``section_limitations.html.j2`` is a symbolic link to a file outside it (a tar keeps
    links): followed, ``{% include %}`` put the auditor's files (a key, ``/proc/self/environ``) into the report."""
    secret = ws / "outside-secret.txt"
    secret.write_text("OUTSIDE-SECRET: the auditor's file\n", encoding="utf-8")
    folder = ws / "templates-link"
    folder.mkdir(exist_ok=True)
    link = folder / "section_limitations.html.j2"
    if not link.is_symlink():
        link.symlink_to(secret)
    return _evidence(ws, "template-link", "--templates", folder)


def _model_file_entry(ws: Path, name: str, path: str) -> list[str]:
    def edit(man: dict[str, Any]) -> None:
        man.setdefault("model_files", {})[path] = "0" * 64

    return _evidence(ws, name, run=_resigned_manifest(ws, f"run-{name}", edit))


def _proc_model_file(ws: Path) -> list[str]:
    """A manifest model-file entry ``/proc/self/pagemap`` (a regular file to ``stat``, hundreds of GB to read),
    the run re-signed: the re-hash never ended."""
    return _model_file_entry(ws, "proc-model", "/proc/self/pagemap")


def _fifo_model_file(ws: Path) -> list[str]:
    """A manifest model-file entry naming a FIFO, the run re-signed: the re-hash waited for a writer for ever."""
    return _model_file_entry(ws, "fifo-model", str(_fifo(ws, "model-fifo.pt")))


def _meta_run(ws: Path, name: str, plant: Callable[[Path], None]) -> list[str]:
    """A copy of the data whose first scene's ``meta/*.json`` is replaced by ``plant(path)``, and a copy of the run
    whose manifest (re-signed) names that data: the evidence reads the scenes' meta (data folders are not signed)."""
    import shutil

    data = ws / f"data-{name}"
    if not data.exists():
        shutil.copytree(ws / "data", data)
        meta = sorted(data.glob("*/meta/*.json"))[0]
        meta.unlink()
        plant(meta)

    def edit(man: dict[str, Any]) -> None:
        man["data"]["path"] = str(data)

    return _evidence(ws, name, run=_resigned_manifest(ws, f"run-{name}", edit))


def _fifo_meta(ws: Path) -> list[str]:
    """A scene ``meta/*.json`` that is a FIFO: read with ``read_text``, the evidence step waited for ever."""
    return _meta_run(ws, "meta-fifo", lambda p: os.mkfifo(p))


def _zero_meta(ws: Path) -> list[str]:
    """A scene ``meta/*.json`` that is a link to ``/dev/zero``: read with ``read_text``, it never ended."""
    return _meta_run(ws, "meta-zero", lambda p: p.symlink_to("/dev/zero"))


def _many_rows(ws: Path) -> list[str]:
    """One shard's ``candidates.parquet`` replaced by 200 000 rows (a few kB on disk), re-sealed and re-signed: the
    issue's 100 million rows in 9 MB filled 8 GB once loaded."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    run, shards = copy_run(ws, "run-many-rows")
    pq.write_table(pa.table({"key": pa.array(["seq00/000000"] * 200_000), "rank": pa.array(range(200_000))}),
                   shards[0] / "candidates.parquet", compression="zstd")
    reseal_shard(run, shards[0].name)
    sign_run(run, load_signing_key())
    return _evidence(ws, "many-rows", run=run)


SHADOW = "import pathlib\npathlib.Path(__file__).with_name('IMPORTED').write_text('x')\nraise SystemExit(99)\n"


def _cwd_shadow(ws: Path) -> list[str]:
    """``python -m assurance verify`` run (a subprocess) from a folder holding a ``jsonschema.py`` and a system file
    (loading it imports jsonschema): the folder's module must not be imported. The row's command is then the same
    refusal in-process, naming that folder's missing run; a shadowed import (or another exit) names itself instead."""
    import subprocess
    import sys

    folder = ws / "applicant-cwd"
    folder.mkdir(exist_ok=True)
    (folder / "jsonschema.py").write_text(SHADOW, encoding="utf-8")
    (folder / "uav-el.toml").write_text((ws / "uav-el.toml").read_text(encoding="utf-8"), encoding="utf-8")
    (folder / "IMPORTED").unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSAFEPATH")}
    proc = subprocess.run([sys.executable, "-m", "assurance", "verify", "no-run"], cwd=folder, env=env,
                          capture_output=True, text=True, timeout=120)
    if (folder / "IMPORTED").exists():
        return ["verify", folder / "the-working-folder's-jsonschema.py-was-imported"]
    if proc.returncode != 2:
        return ["verify", folder / f"python-m-assurance-exited-{proc.returncode}"]
    return ["verify", folder / "no-run"]


def _braces_camera(ws: Path) -> list[str]:
    """A system file whose camera is named ``Cam {A} {confidence:pct}``: the registry's texts failed to render,
    blaming the packaged requirements.yaml (or printed "95%"); the name is a fact, shown as written."""
    system = _system(ws, "sys-braces", '[camera]\nname = "Cam {A} {confidence:pct}"\n')
    return [*_evidence(ws, "braces"), "--system", system]


def _feb30_waiver(ws: Path) -> list[str]:
    """A waiver dated 2026-02-30: the YAML parser failed with "day is out of range for month", naming neither
    the file nor the waiver."""
    path = ws / "waiver-feb30.yaml"
    path.write_text("waivers:\n  - id: EL-R10\n    reason: later\n    tracked_by: none\n"
                    "    owner: segmentation maintainers\n    expires: 2026-02-30\n", encoding="utf-8")
    return _evidence(ws, "feb30-waiver", "--waivers", path)


def _hierarchy_link_outside(ws: Path) -> list[str]:
    """A label set (UAVid's, copied) naming ``hierarchy: tree.yaml``, a symbolic link to a file outside its folder."""
    folder = ws / "labels-link"
    folder.mkdir(exist_ok=True)
    outside = ws / "outside-tree.yaml"
    outside.write_text("root: any\nchildren:\n  any: [safe, unsafe]\n  safe: [clutter, tree, low_vegetation, human]\n"
                       "  unsafe: [building, road, static_car, moving_car]\n", encoding="utf-8")
    link = folder / "tree.yaml"
    if not link.is_symlink():
        link.symlink_to(outside)
    labels = folder / "uavid-linked.yaml"
    labels.write_text((PRESET_DIR / "uavid.yaml").read_text(encoding="utf-8").replace("name: uavid", "name: linked")
                      + "\nhierarchy: tree.yaml\n", encoding="utf-8")
    return _land(ws, _system(ws, "sys-hierarchy-link", f'[labels]\nfile = "{labels}"\n'))


TRUST_CASES: tuple[Case, ...] = (
    Case("T5-fifo-labels", "a system file whose [labels] file is a FIFO", _fifo_labels, 2, "a FIFO"),
    Case("T6-dev-zero-labels", "a system file whose [labels] file is a link to /dev/zero", _zero_labels, 2,
         "a character device"),
    Case("T7-fifo-waivers", "evidence --waivers FIFO", lambda ws: _evidence(ws, "fifo-waivers", "--waivers",
                                                                            _fifo(ws, "waivers-fifo.yaml")), 2,
         "a FIFO"),
    Case("T8-fifo-targets", "evidence --targets FIFO", lambda ws: _evidence(ws, "fifo-targets", "--targets",
                                                                            _fifo(ws, "targets-fifo.json")), 2,
         "a FIFO"),
    Case("T9-huge-poses", "a 200 MB poses.csv flown under the sidecar pose policy", _huge_poses, 2,
         "exceeds the limit"),
    Case("T10-deep-toml", "a system file nested 60 000 brackets deep", _deep_toml, 2, "nested more than"),
    Case("T11-nan-target", "a system file with [targets] unsafe_landing_bound = nan, given to campaign", _nan_target,
         2, "must be a finite number"),
    Case("T12-readable-key", "campaign --signing-key KEY where KEY has mode 0644", _readable_key, 2, "chmod 600"),
    Case("T13-out-inside-run", "evidence --out RUN/shards/report", _out_inside_run, 2,
         "lies inside the campaign run"),
    Case("T14-waiver-version-999", "a waiver of EL-R10 by a declared owner expiring at version 999.0.0",
         _version_waiver, 1, "beyond the next minor release", "expires at version"),
    Case("T15-manifest-missing-tasks", "a manifest naming a task outside the data, the run re-signed",
         _missing_tasks, 1, "with no readouts", "with no readouts"),
    Case("T16-gate-threshold-1e300", "the shipped frame gate re-hashed at threshold 1e300, in a system file",
         _gate_1e300, 2, "lies above the highest score"),
    Case("T17-card-threshold-1e300", "the shipped calibration card re-hashed at threshold 1e300, in a system file",
         _card_1e300, 2, "outside the score range"),
    Case("T21-fifo-template", "evidence --templates DIR where DIR/auditor_issre.html.j2 is a FIFO", _fifo_template, 2,
         "a FIFO"),
    Case("T30-template-link-outside", "evidence --templates DIR where DIR/section_limitations.html.j2 is a symbolic "
         "link to a file outside DIR", _template_link_outside, 2, "outside its folder"),
    Case("T31-manifest-proc-model-file", "a manifest model-file entry /proc/self/pagemap, the run re-signed",
         _proc_model_file, 1, "under /proc", "/proc/self/pagemap"),
    Case("T32-fifo-scene-meta", "a scene meta/*.json that is a FIFO, in the data of a re-signed run", _fifo_meta, 1,
         "gate:", "gate:"),
    Case("T33-parquet-too-many-rows", "one shard's candidates.parquet of 200 000 rows, re-sealed and re-signed",
         _many_rows, 2, "rows exceeds the limit"),
    Case("T34-cwd-shadowing-module", "python -m assurance verify run from a folder holding a jsonschema.py",
         _cwd_shadow, 2, "applicant-cwd/no-run: not a campaign run"),
    Case("T35-braces-in-camera-name", 'evidence --system FILE where [camera] name = "Cam {A} {confidence:pct}"',
         _braces_camera, 1, "gate:", "gate:"),
    Case("T36-waiver-invalid-date", "evidence --waivers FILE with a waiver of EL-R10 dated 2026-02-30",
         _feb30_waiver, 2, "waiver 1 (EL-R10): expires must be a date"),
    Case("T37-dev-zero-scene-meta", "a scene meta/*.json that is a link to /dev/zero, in the data of a re-signed run",
         _zero_meta, 1, "gate:", "gate:"),
    Case("T38-hierarchy-link-outside", "a label set whose hierarchy file is a symbolic link out of its folder",
         _hierarchy_link_outside, 2, "outside its folder"),
    Case("T39-manifest-fifo-model-file", "a manifest model-file entry naming a FIFO, the run re-signed",
         _fifo_model_file, 1, "a FIFO", "model-fifo.pt"),
)
