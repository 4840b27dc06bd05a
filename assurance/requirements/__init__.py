"""Safety requirements: the registry, the verification states, and the campaign checks (docs/architecture.md 4.6).

- ``registry``: ``assurance/requirements.yaml`` read and validated (``load_registry``, ``RegistryError``);
- ``targets``: the parameters a user sets (``TARGETS``, ``validate_targets``, ``TargetError``) and the
  requirement texts rendered from them (``render_text``);
- ``states``: test outcomes -> verified / failed / not verified (``requirement_state``, ``evaluate``) and
  the results document the pytest plugin writes;
- ``records``: ``Evidence``, what a campaign check returns (pass, fail or insufficient);
- ``checks`` and ``determinism``: the campaign checks, plain functions of a run's readouts and table;
- ``catalogue``: the check registry (``@check``, ``CheckContext``, ``CHECKS``), and ``campaign_checks``
  the registered checks, one or more per campaign-judged requirement (section 4.8).

The campaign requirement tests (``tests/requirements``) run every registered check and turn
``insufficient`` into a skip (so the requirement is "not verified", never "failed"); the evidence
report shows the same records as supporting detail. ``import assurance.requirements as rq`` gives
every public name.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    "ARTEFACTS": "assurance.requirements.catalogue",
    "CHECKS": "assurance.requirements.catalogue",
    "Check": "assurance.requirements.catalogue",
    "CheckContext": "assurance.requirements.catalogue",
    "Evidence": "assurance.requirements.records",
    "FAIL": "assurance.requirements.records",
    "FAILED": "assurance.requirements.states",
    "FAILING": "assurance.requirements.states",
    "INSUFFICIENT": "assurance.requirements.records",
    "KNOWN_SOURCES": "assurance.requirements.registry",
    "NOT_VERIFIED": "assurance.requirements.states",
    "OUTCOMES": "assurance.requirements.states",
    "PASS": "assurance.requirements.records",
    "PASSING": "assurance.requirements.states",
    "REGISTRY_FORMAT": "assurance.requirements.registry",
    "REQUIRED_TARGETS": "assurance.requirements.targets",
    "RESULTS_FORMAT": "assurance.requirements.states",
    "Registry": "assurance.requirements.registry",
    "RegistryError": "assurance.requirements.registry",
    "Requirement": "assurance.requirements.registry",
    "RequirementResult": "assurance.requirements.states",
    "STATES": "assurance.requirements.states",
    "TARGETS": "assurance.requirements.targets",
    "TIMING_COLUMNS": "assurance.requirements.determinism",
    "TargetError": "assurance.requirements.targets",
    "TestOutcome": "assurance.requirements.states",
    "VERIFIED": "assurance.requirements.states",
    "artefacts_of": "assurance.requirements.catalogue",
    "card_path": "assurance.paths",
    "check": "assurance.requirements.catalogue",
    "check_artefacts_identified": "assurance.requirements.checks",
    "check_decision_time": "assurance.requirements.checks",
    "check_monitor_coverage": "assurance.requirements.checks",
    "check_perturbation_coverage": "assurance.requirements.checks",
    "check_pose_margin": "assurance.requirements.checks",
    "check_rerun": "assurance.requirements.determinism",
    "check_safety_gain": "assurance.requirements.checks",
    "check_table_recomputation": "assurance.requirements.determinism",
    "check_target": "assurance.requirements.targets",
    "check_unsafe_landing_bound": "assurance.requirements.checks",
    "checks_of": "assurance.requirements.catalogue",
    "confidence_text": "assurance.requirements.checks",
    "config_sha256": "assurance.requirements.checks",
    "default_registry_path": "assurance.requirements.registry",
    "evaluate": "assurance.requirements.states",
    "images_needed": "assurance.requirements.checks",
    "load_registry": "assurance.requirements.registry",
    "load_results": "assurance.requirements.states",
    "pose_margin": "assurance.requirements.checks",
    "own_poses": "assurance.requirements.checks",
    "worst_required_beta": "assurance.requirements.checks",
    "read_targets_file": "assurance.requirements.targets",
    "render_text": "assurance.requirements.targets",
    "requirement_state": "assurance.requirements.states",
    "requirements_reading": "assurance.requirements.catalogue",
    "results_document": "assurance.requirements.states",
    "summary_counts": "assurance.requirements.states",
    "targets_sha256": "assurance.requirements.targets",
    "validate_targets": "assurance.requirements.targets",
}
_SUBMODULES = ("catalogue",)  # the check registry: served with the checks registered


def __getattr__(name: str) -> Any:
    """The public names, imported on first use (PEP 562): the pytest plugin (``assurance.requirements.pytest_plugin``,
    loaded by every pytest session in an environment with the toolkit) imports this package, and must import nothing
    heavy (numpy, the checks, the flight code) until a session asks for a run. The checks register themselves
    (``campaign_checks``) before any name is served."""
    if name in _WHERE or name in _SUBMODULES:
        importlib.import_module(f"{__name__}.campaign_checks")  # registers the checks
        if name in _SUBMODULES:
            return importlib.import_module(f"{__name__}.{name}")
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])


__all__ = [
    "validate_targets",
    "targets_sha256",
    "render_text",
    "read_targets_file",
    "card_path",
    "check_target",
    "TargetError",
    "TARGETS",
    "REQUIRED_TARGETS",
    "ARTEFACTS",
    "CHECKS",
    "FAIL",
    "FAILED",
    "FAILING",
    "INSUFFICIENT",
    "KNOWN_SOURCES",
    "NOT_VERIFIED",
    "OUTCOMES",
    "PASS",
    "PASSING",
    "REGISTRY_FORMAT",
    "RESULTS_FORMAT",
    "STATES",
    "TIMING_COLUMNS",
    "VERIFIED",
    "Check",
    "CheckContext",
    "Evidence",
    "Registry",
    "RegistryError",
    "Requirement",
    "RequirementResult",
    "TestOutcome",
    "artefacts_of",
    "check",
    "check_artefacts_identified",
    "check_decision_time",
    "check_monitor_coverage",
    "check_perturbation_coverage",
    "check_pose_margin",
    "check_rerun",
    "check_safety_gain",
    "check_table_recomputation",
    "check_unsafe_landing_bound",
    "checks_of",
    "confidence_text",
    "config_sha256",
    "default_registry_path",
    "evaluate",
    "images_needed",
    "load_registry",
    "load_results",
    "pose_margin",
    "own_poses",
    "worst_required_beta",
    "requirement_state",
    "requirements_reading",
    "results_document",
    "summary_counts",
]
