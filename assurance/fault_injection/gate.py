"""Fault-injection cases: a gate that verifies what it says, and models bound to the run (``G1``..``G9``).

Each case forges what a hostile user would (a deselected or uncollectable requirement test, a weaker registry or
targets, a waiver of a passing requirement, a model file re-hashed after the run, an edited manifest, a
calibration card judged on training scenes) and returns the ``uav-el`` command that must refuse it. The cases that
need requirement results run ``uav-el verify`` on the workspace's run once (``_verified``).
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

from assurance.code_identity import install_root
from assurance.fault_injection.case import Case, campaign_argv, copy_run, prepare, save_tiny_weights
from assurance.requirements.registry import default_registry_path
from el.flight.pipeline import PipelineConfig


def _verified(ws: Path, run: Path | None = None, name: str = "ver", *extra: object) -> Path:
    """``uav-el verify`` of ``run`` (the workspace's) into ``WS/name`` (once); the results file."""
    out = ws / name
    if not (out / "requirements.json").is_file():
        prepare(["verify", run or ws / "run", "--out", out, *extra])
    return out / "requirements.json"


def _evidence(ws: Path, name: str, *extra: object, run: Path | None = None) -> list[str]:
    return ["evidence", "--run", str(run or ws / "run"), "--out", str(ws / f"rep-{name}"), "--no-pdf", "--boot", "20",
            *map(str, extra)]


def _deselected(ws: Path) -> list[str]:
    """EL-R04's test left out with -k: its requirement is 'not verified', and not undecidable at any size."""
    results = _verified(ws, None, "ver-deselected", "-k", "not monitor_coverage")
    return _evidence(ws, "deselected", "--requirements", results)


def _uncollectable(ws: Path) -> list[str]:
    """A user's requirement test file that does not even import: the session decides nothing."""
    broken = ws / "test_broken_requirement.py"
    broken.write_text("import pytest\n\n@pytest.mark.requirements('EL-R04')\ndef test_x(:\n    pass\n")
    return ["verify", ws / "run", "--out", ws / "ver-broken", "--tests", broken]


def _weak_registry_file(ws: Path) -> Path:
    text = default_registry_path().read_text(encoding="utf-8")
    path = ws / "weak-registry.yaml"
    path.write_text(text.replace("unsafe_landing_bound: 0.05", "unsafe_landing_bound: 0.999")
                    .replace("min_images_per_perturbation: 10", "min_images_per_perturbation: 1"), encoding="utf-8")
    return path


def _weak_registry(ws: Path) -> list[str]:
    """A registry with bound 0.999 and 1 image per perturbation, given to both verify and evidence (so the results
    and the report agree with each other): weaker than the system's, parameter by parameter."""
    weak = _weak_registry_file(ws)
    results = _verified(ws, None, "ver-weak", "--registry", weak)
    return _evidence(ws, "weak", "--registry", weak, "--requirements", results)


def _weak_targets(ws: Path) -> list[str]:
    path = ws / "weak-targets.json"
    path.write_text(json.dumps({"unsafe_landing_bound": 0.999, "confidence": 0.5}), encoding="utf-8")
    results = _verified(ws, None, "ver-weak-targets", "--targets", path)
    return _evidence(ws, "weak-targets", "--targets", path, "--requirements", results)


def _waived_pass(ws: Path) -> list[str]:
    """A well-formed waiver (declared owner, near expiry) of EL-R01, which the results verify."""
    import datetime as dt

    expires = (dt.date.today() + dt.timedelta(days=30)).isoformat()
    path = ws / "waive-verified.yaml"
    path.write_text(f"waivers:\n  - id: EL-R01\n    reason: hide it\n    tracked_by: none\n"
                    f"    owner: safety engineering\n    expires: {expires}\n", encoding="utf-8")
    results = _verified(ws, None, "ver-waived", "--waivers", path)  # the results pin the waivers the report applies
    return _evidence(ws, "waived-pass", "--waivers", path, "--requirements", results)


def _edited_manifest(ws: Path) -> list[str]:
    """The manifest says 70 images where the campaign evaluated 2 (the task list untouched)."""
    run, _ = copy_run(ws, "run-manifest")
    man = json.loads((run / "manifest.json").read_text(encoding="utf-8"))
    man["data"]["images"] = 70
    (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True), encoding="utf-8")
    return _evidence(ws, "manifest", run=run)


def _resign(path: Path, **body: object) -> None:
    """Edit a self-hashed card's body and recompute the hash it carries about itself (as a forger would)."""
    doc = json.loads(path.read_text(encoding="utf-8"))
    doc["body"].update(body)
    doc["sha256"] = hashlib.sha256(json.dumps(doc["body"], sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    path.write_text(json.dumps(doc), encoding="utf-8")


def _resigned_monitor(ws: Path) -> list[str]:
    """A run made with a learned monitor file, which is then made to accept every candidate and re-hashed."""
    model = ws / "learned-copy.json"
    shutil.copy(install_root() / "el/monitors/data/learned.json", model)
    run = ws / "run-learned"
    argv = campaign_argv(ws, run)
    argv[argv.index("--weights"):argv.index("--weights") + 2] = []  # the shipped network, the monitor's own
    argv[argv.index("--monitors") + 1] = f"learned:model={model}"
    prepare(argv)
    _resign(model, intercept=-100.0, threshold=0.99)
    return _evidence(ws, "resigned", run=run)


def _changed_weights(ws: Path) -> list[str]:
    """The run's network weights replaced after the run by others, with their own matching card."""
    weights, run = ws / "tiny-swapped.pt", ws / "run-swapped"
    shutil.copy(ws / "tiny.pt", weights)
    shutil.copy(ws / "tiny.json", weights.with_suffix(".json"))
    prepare(campaign_argv(ws, run, weights=weights))
    save_tiny_weights(weights, nan=True)
    return _evidence(ws, "swapped", run=run)


def _training_split(ws: Path) -> list[str]:
    """EL-R16 asked of two training-split scenes, with the deployed monitor and its calibration card."""
    data, run = ws / "data-train", ws / "run-train"
    prepare(["synth", "--out", data, "--split", "train", "--scenes", "2", "--size", "320x180", "--no-progress"])
    argv = campaign_argv(ws, run, data=data)
    argv[argv.index("--weights"):argv.index("--weights") + 2] = []
    argv[argv.index("--monitors") + 1] = PipelineConfig().monitor
    prepare(argv)
    return ["verify", run, "--out", ws / "ver-train", "-k", "calibrated_miss_rate"]


GATE_CASES: tuple[Case, ...] = (
    Case("G1-deselected-test", "verify -k 'not monitor_coverage' (EL-R04's test left out), then evidence",
         _deselected, 1, "not verified: EL-R04", "gate:"),
    Case("G2-uncollectable-test", "verify --tests FILE where FILE has a syntax error", _uncollectable, 2,
         "could not be collected"),
    Case("G3-weakened-registry", "a registry with unsafe_landing_bound 0.999 and 1 image per perturbation, given "
         "to verify and evidence", _weak_registry, 1, "unsafe_landing_bound = 0.999", "gate:"),
    Case("G4-weakened-targets", "targets unsafe_landing_bound 0.999 and confidence 0.5 given to verify and "
         "evidence", _weak_targets, 1, "is lower (looser) than the system's 0.95", "gate:"),
    Case("G5-waiver-of-a-pass", "a well-formed waiver of EL-R01, which the results verify", _waived_pass, 1,
         "names EL-R01", "gate:"),
    Case("G6-edited-manifest", "manifest.json says 70 images for a 2-image run", _edited_manifest, 4,
         "manifest.json"),
    Case("G7-resigned-monitor", "the run's learned monitor file made to accept every candidate and re-hashed "
         "after the run", _resigned_monitor, 1, "changed since the run was made", "gate:"),
    Case("G8-swapped-weights", "the run's weights file (and its card) replaced by other weights after the run",
         _changed_weights, 1, "tiny-swapped.pt: changed since the run was made", "gate:"),
    Case("G9-el-r16-training-split", "EL-R16 asked of two training-split scenes with the deployed card",
         _training_split, 0, "the run's scenes declare the split", "EL-R16:"),
)
