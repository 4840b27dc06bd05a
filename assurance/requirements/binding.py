"""The run binding of a requirement test session: which campaign run it judges, and the facts that tie its
results to that run (docs/architecture.md 4.6).

The pytest plugin (``assurance.requirements.pytest_plugin``) calls ``bind_run`` at configure time, so every
session with the plugin (the packaged checks, ``uav-el verify``, a user's own ``@pytest.mark.requirements``
tests in any folder) records the run digest, the run's system file hash and its targets; the code identity
and the registry hash are added when the results are written. The evidence gate refuses results bound to
another run, code, registry, targets or system file.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

from assurance.campaign.integrity import verify_run
from assurance.campaign.readouts import RunError, read_manifest
from assurance.system.loader import system_from_record

log = logging.getLogger(__name__)

RUN_ENV = "UAV_EL_RUN"
"""The environment variable naming the campaign run when ``--uav-el-run`` is not given."""
DEFAULT_RUN = Path("runs") / "demo"
"""The run judged when none is given (under the rootdir): the README's demo run."""


def run_path(option: str | None, ini: str | None, base: Path) -> Path:
    """The campaign run a session judges: the option, else ``$UAV_EL_RUN``, else the ini value (relative to
    ``base``, the ini file's folder), else ``runs/demo`` under ``base``."""
    given = option or os.environ.get(RUN_ENV)
    if given:
        return Path(given).resolve()
    if ini:
        return (base / ini).resolve()
    return (base / DEFAULT_RUN).resolve()


def run_facts(run: Path) -> dict[str, Any]:
    """What the session records about its run: path, whether it exists, its digest (None when damaged, with
    the problems), the system file's hash and the targets the run's system file sets (with their source)."""
    facts: dict[str, Any] = {"run": str(run), "run_exists": (run / "manifest.json").is_file()}
    if not facts["run_exists"]:
        return facts

    try:
        check = verify_run(run)
    except RunError as exc:
        facts.update(run_digest=None, run_problems=[str(exc)])
    else:
        facts.update(run_digest=check.digest if check.ok else None, run_problems=check.problems)
        if check.problems:
            log.warning("campaign run %s is damaged: %s", run, "; ".join(check.problems[:3]))
    facts.update(system_of_run(run))
    return facts


def system_of_run(run: Path) -> dict[str, Any]:
    """The run's system file as the requirement results record it: its hash, and the targets of a system file
    that is not the embedded default (``_targets``, ``_targets_source``: applied by the plugin, not recorded)."""
    try:  # bounded: the applicant's run folder
        record = read_manifest(run).get("system") or {}
    except (OSError, ValueError, AttributeError):
        return {"system_sha256": None}
    out: dict[str, Any] = {"system_sha256": record.get("sha256")}
    if record and not record.get("default"):
        system = system_from_record(record)
        out["_targets"] = system.targets()
        out["_targets_source"] = f"{system.label} [targets]"
    return out
