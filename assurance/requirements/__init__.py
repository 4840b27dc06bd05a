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

from assurance.paths import card_path
from assurance.requirements import campaign_checks  # noqa: F401  (registers the checks)
from assurance.requirements.catalogue import (
    ARTEFACTS,
    CHECKS,
    Check,
    CheckContext,
    artefacts_of,
    check,
    checks_of,
    requirements_reading,
)
from assurance.requirements.checks import (
    check_artefacts_identified,
    check_decision_time,
    check_monitor_coverage,
    check_perturbation_coverage,
    check_pose_margin,
    check_safety_gain,
    check_unsafe_landing_bound,
    confidence_text,
    config_sha256,
    images_needed,
    pose_margin,
)
from assurance.requirements.determinism import TIMING_COLUMNS, check_rerun, check_table_recomputation
from assurance.requirements.records import FAIL, INSUFFICIENT, PASS, Evidence
from assurance.requirements.registry import (
    KNOWN_SOURCES,
    REGISTRY_FORMAT,
    Registry,
    RegistryError,
    Requirement,
    default_registry_path,
    load_registry,
)
from assurance.requirements.states import (
    FAILED,
    FAILING,
    NOT_VERIFIED,
    OUTCOMES,
    PASSING,
    RESULTS_FORMAT,
    STATES,
    VERIFIED,
    RequirementResult,
    TestOutcome,
    evaluate,
    load_results,
    requirement_state,
    results_document,
    summary_counts,
)
from assurance.requirements.targets import (
    REQUIRED_TARGETS,
    TARGETS,
    TargetError,
    check_target,
    read_targets_file,
    render_text,
    targets_sha256,
    validate_targets,
)

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
    "requirement_state",
    "requirements_reading",
    "results_document",
    "summary_counts",
]
