"""pytest plugin: the ``requirements`` marker that ties tests to safety requirements, and the binding of a test
session to a campaign run (docs/architecture.md section 4.6).

Registered with the ``pytest11`` entry point ``uav_el_requirements``, so every pytest session in an environment
where the toolkit is installed has it: the packaged checks (``uav-el verify``, or
``pytest --pyargs assurance.requirements.suite``) and a user's own tests in any folder alike.

- ``@pytest.mark.requirements("EL-R01", ...)`` claims requirements of the registry
  (``assurance/requirements.yaml``, or ``--uav-el-registry PATH``). An id the registry does not
  know, or a marker without ids, stops the session at collection (``pytest.UsageError`` naming the
  test and the id). A test may carry several markers (function, class, module): all count.
  ``pytest -m requirements`` runs exactly the tests that claim a requirement. The ``campaign`` and
  ``slow`` markers are registered here too.
- The claimed ids are added to the test's ``user_properties`` as one property named ``requirements``
  (comma-joined, e.g. ``EL-R03,EL-R04``), so ``pytest --junitxml=...`` carries them.
- The session is bound to a campaign run (``--uav-el-run RUN``, else ``$UAV_EL_RUN``, else ini ``uav_el_run``,
  else ``runs/demo`` under the rootdir; ``assurance.requirements.binding``): the run's digest and system file
  hash are recorded, the run's system file sets the targets, and the fixtures ``campaign_run`` (skips when
  there is no run: "not verified") and ``requirement_registry`` serve any test.
- At the end of the session each requirement of the registry gets a state (verified / failed /
  not verified, see ``assurance.requirements.requirement_state``) and the results go to a JSON file,
  with the code identity (``assurance.code_identity``) and the registry's hash:
  ``--uav-el-report PATH`` (or ini ``uav_el_report``), or ``reports/requirements.json`` under the
  rootdir when the marker expression selects the requirement tests (``-m requirements``).
- The requirement targets (the registry's parameters a user sets, ``assurance.requirements.targets``):
  ``--uav-el-targets FILE.json`` (a JSON object of overrides), else ``$UAV_EL_TARGETS``, else ini
  ``uav_el_targets``; a plugin or conftest binds them in code with ``set_targets(config, targets, source=...)``
  before collection. The overrides, their source and the effective parameters' SHA-256 go into the results
  JSON (``registry``), and the evidence gate refuses a report on other targets.

Every option has the prefix ``--uav-el-``; ``--requirements-report`` and ``--requirements-registry`` remain as
aliases. Ini options (``[tool.pytest.ini_options]``) give the defaults, relative to the ini file's folder.
State lives in ``config.stash``. ``set_context(config, **values)`` lets a conftest add facts to the report.
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from assurance import requirements as rq  # the package's names load on first use (its __getattr__), not here
from assurance.files import atomic_write_bytes

MARKER = "requirements"
DEFAULT_REPORT = Path("reports") / "requirements.json"
TARGETS_ENV = "UAV_EL_TARGETS"
"""The environment variable naming a targets JSON file when ``--uav-el-targets`` is not given."""
RUN_ENV = "UAV_EL_RUN"
MARKERS = {
    "campaign": "checks a campaign run's readouts (the evidence step, uav-el verify); excluded from a fast run",
    "slow": "long-running tests (campaigns, training); excluded from a fast run",
}
"""The other markers the plugin registers (a project that uses --strict-markers needs them declared)."""

_REGISTRY = pytest.StashKey[Any]()
_CLAIMS = pytest.StashKey[dict[str, tuple[str, ...]]]()
_PHASES = pytest.StashKey[dict[str, list[Any]]]()
_DESELECTED = pytest.StashKey[set[str]]()
_CONTEXT = pytest.StashKey[dict[str, Any]]()
_ERRORS = pytest.StashKey[list[str]]()
_WRITTEN = pytest.StashKey[Any]()
_TARGETS = pytest.StashKey[Any]()
_BOUND = pytest.StashKey[bool]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("uav-el requirements", "safety requirements (assurance/requirements.yaml)")
    group.addoption("--uav-el-run", dest="uav_el_run", metavar="RUN", default=None,
                    help="campaign run the requirement checks judge and the results are bound to "
                         f"(default: ${RUN_ENV}, else ini uav_el_run, else runs/demo under the rootdir)")
    group.addoption("--uav-el-report", "--requirements-report", dest="requirements_report", metavar="PATH",
                    default=None,
                    help="write the per-requirement results (tests, outcomes, state) to this JSON file "
                         f"(default: ini uav_el_report; with -m requirements: {DEFAULT_REPORT} under the rootdir)")
    group.addoption("--uav-el-registry", "--requirements-registry", dest="requirements_registry", metavar="PATH",
                    default=None, help="requirement registry to check marker ids against (default: ini "
                                       "uav_el_registry, else the shipped assurance/requirements.yaml)")
    group.addoption("--uav-el-targets", dest="uav_el_targets", metavar="FILE.json", default=None,
                    help="requirement targets overriding the registry's parameters (a JSON object, e.g. "
                         '{"confidence": 0.99, "radius_m": 2.5}; default: $' + TARGETS_ENV
                         + ", else ini uav_el_targets, else none)")
    for name, what in (("uav_el_run", "campaign run folder (--uav-el-run)"),
                       ("uav_el_report", "requirement results JSON (--uav-el-report)"),
                       ("uav_el_registry", "requirement registry YAML (--uav-el-registry)"),
                       ("uav_el_targets", "requirement targets JSON (--uav-el-targets)")):
        parser.addini(name, f"uav-el: default {what}, relative to the ini file's folder", default="")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        f"{MARKER}(*ids): the test verifies these safety requirements (ids of assurance/requirements.yaml, "
        "e.g. 'EL-R01'); select them with -m requirements",
    )
    for name, text in MARKERS.items():
        config.addinivalue_line("markers", f"{name}: {text}")
    for key, empty in ((_REGISTRY, None), (_CLAIMS, {}), (_PHASES, {}), (_DESELECTED, set()), (_CONTEXT, {}),
                       (_ERRORS, []), (_WRITTEN, None), (_TARGETS, None)):
        config.stash.setdefault(key, empty)  # a conftest may have set its context first
    config.pluginmanager.register(_Recorder(config), "uav_el_requirements_recorder")
    if _setting(config, "requirements_registry", "uav_el_registry") or _targets_file(config):
        registry(config)  # a bad registry or targets file given on the command line is a usage error at once
    if _run_asked(config):
        _bind(config)
    # else bound when the session asks for a run (a test claiming a requirement or using the campaign_run or
    # requirement_registry fixture, or a report to write): a session that does not pays nothing here


RUN_FIXTURES = ("campaign_run", "requirement_registry")


def _run_asked(config: pytest.Config) -> bool:
    """Whether the session names a campaign run (option, ``$UAV_EL_RUN`` or ini ``uav_el_run``)."""
    return bool(config.getoption("uav_el_run", None) or os.environ.get(RUN_ENV) or config.getini("uav_el_run"))


def _bind(config: pytest.Config) -> None:
    """Bind the session to its campaign run (``assurance.requirements.binding``): digest, system file, targets;
    once (an xdist worker never: the controller binds)."""
    if hasattr(config, "workerinput") or config.stash.get(_BOUND, False):
        return
    config.stash[_BOUND] = True
    from assurance.requirements import binding  # deferred: loads pandas and the campaign readouts; plugin stays light

    run = binding.run_path(config.getoption("uav_el_run", None), str(config.getini("uav_el_run") or ""),
                           _ini_base(config))
    facts = binding.run_facts(run)
    targets, source = facts.pop("_targets", None), facts.pop("_targets_source", None)
    set_context(config, **facts)
    if targets is not None:
        set_targets(config, targets, source=source)


def _ini_base(config: pytest.Config) -> Path:
    return config.inipath.parent if config.inipath else config.rootpath


def _setting(config: pytest.Config, dest: str, ini: str, env: str | None = None) -> str | None:
    """An option's value: the command line, else the environment variable ``env``, else the ini value
    (made absolute against the ini file's folder), else None."""
    given = config.getoption(dest, None) or (os.environ.get(env) if env else None)
    if given:
        return str(given)
    value = str(config.getini(ini) or "")
    return str(_ini_base(config) / value) if value else None


def _targets_file(config: pytest.Config) -> str | None:
    return _setting(config, "uav_el_targets", "uav_el_targets", TARGETS_ENV)


def set_targets(config: pytest.Config, targets: Any, *, source: str = "set_targets") -> None:
    """Bind the session's requirement targets in code (e.g. from a system file's ``[targets]``), replacing
    ``--uav-el-targets`` / ``$UAV_EL_TARGETS``. Call it before collection (``pytest_configure`` of a plugin
    or conftest); the overrides are validated at once (UsageError naming the key)."""
    config.stash[_TARGETS] = (dict(targets or {}), source)
    config.stash[_REGISTRY] = None
    registry(config)


def registry(config: pytest.Config) -> Any:
    """The session's validated requirement registry with the session's targets applied (loaded once;
    UsageError if the registry or a target is invalid)."""
    reg = config.stash.get(_REGISTRY, None)
    if reg is None:
        try:
            bound = config.stash.get(_TARGETS, None)
            if bound is None and _targets_file(config):
                path = _targets_file(config)
                bound = (rq.read_targets_file(path), str(Path(path).resolve()))
            targets, source = bound or ({}, None)
            reg = rq.load_registry(_setting(config, "requirements_registry", "uav_el_registry"), targets=targets,
                                   targets_source=source)
        except (rq.RegistryError, rq.TargetError) as exc:
            raise pytest.UsageError(f"requirement registry: {exc}") from None
        config.stash[_REGISTRY] = reg
    return reg


def set_context(config: pytest.Config, **values: Any) -> None:
    """Record facts about the session in the requirement report (``context``), e.g. ``run=...``."""
    config.stash.setdefault(_CONTEXT, {}).update(values)


def get_context(config: pytest.Config) -> dict[str, Any]:
    """The facts recorded so far for the requirement report (a copy)."""
    return dict(config.stash.get(_CONTEXT, {}))


@pytest.fixture(scope="session")
def requirement_registry(pytestconfig: pytest.Config) -> Any:
    """The session's validated requirement registry, with the session's targets applied."""
    return registry(pytestconfig)


@pytest.fixture(scope="session")
def campaign_run(pytestconfig: pytest.Config) -> Path:
    """The campaign run the session is bound to; skips (requirement not verified) when there is none or it is
    damaged, so too little evidence never fails a requirement."""
    ctx = get_context(pytestconfig)
    run = Path(ctx.get("run") or "runs/demo")
    if not ctx.get("run_exists"):
        pytest.skip(f"not verified: no campaign run at {run} (pass --uav-el-run RUN or set {RUN_ENV}; "
                    "make one with: uav-el campaign --data DATA --out RUN)")
    if ctx.get("run_problems"):
        pytest.skip(f"not verified: the campaign run {run} is damaged: {'; '.join(ctx['run_problems'][:3])}")
    return run


def claimed_ids(item: pytest.Item) -> tuple[str, ...]:
    """Every requirement id claimed by the test's ``requirements`` markers (all levels), in order."""
    ids: list[str] = []
    for mark in item.iter_markers(MARKER):
        ids.extend(mark.args)
    return tuple(dict.fromkeys(ids))


class _Recorder:
    """The plugin's per-session hooks (one instance per config, so nested pytester sessions stay apart)."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config

    @pytest.hookimpl(tryfirst=True)
    def pytest_collection_modifyitems(self, session: pytest.Session, config: pytest.Config,
                                      items: list[pytest.Item]) -> None:
        claims = config.stash[_CLAIMS]
        problems: list[str] = []
        if any(item.get_closest_marker(MARKER) or set(RUN_FIXTURES) & set(getattr(item, "fixturenames", ()))
               for item in items):
            _bind(config)  # the session asks for a run: bound before any test uses its registry or targets
        for item in items:
            marks = list(item.iter_markers(MARKER))
            if not marks:
                continue
            reg = registry(config)
            for mark in marks:
                if not mark.args:
                    problems.append(f"{item.nodeid}: @pytest.mark.{MARKER}() names no requirement id")
                for rid in mark.args:
                    if not isinstance(rid, str):
                        problems.append(f"{item.nodeid}: requirement id {rid!r} is not a string")
                    elif rid not in reg:
                        problems.append(f"{item.nodeid}: unknown requirement id {rid!r}")
            ids = tuple(r for r in claimed_ids(item) if isinstance(r, str))
            claims[item.nodeid] = ids
            if ids:  # one comma-joined property (the form test-management tools import from JUnit XML)
                item.user_properties.append((MARKER, ",".join(ids)))
        if problems:
            reg = registry(config)
            raise pytest.UsageError(
                f"requirements marker: {len(problems)} problem(s) (registry {reg.path}, "
                f"ids {reg.ids[0]}..{reg.ids[-1]}):\n  " + "\n  ".join(problems))

    def pytest_deselected(self, items: list[pytest.Item]) -> None:
        self.config.stash[_DESELECTED].update(i.nodeid for i in items)

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        if report.failed:
            self.config.stash[_ERRORS].append(f"{report.nodeid or '<session>'}: {_crash_message(report)}")

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if any(k == MARKER for k, _ in report.user_properties):
            self.config.stash[_PHASES].setdefault(report.nodeid, []).append(report)

    def pytest_sessionstart(self, session: pytest.Session) -> None:
        self.config.stash[_CONTEXT].setdefault("started", time.strftime("%Y-%m-%dT%H:%M:%S%z"))

    def pytest_sessionfinish(self, session: pytest.Session, exitstatus: int) -> None:
        config = self.config
        if hasattr(config, "workerinput") or config.getoption("collectonly"):
            return  # an xdist worker (the controller writes the report), or nothing was run
        path = _report_path(config)
        if path is None:
            return
        _bind(config)  # a report is always bound to its run (or records that there is none)
        results = session_results(config)
        context = dict(config.stash[_CONTEXT])
        from assurance.code_identity import code_identity  # deferred: imports el; every pytest session loads the plugin

        code = code_identity()
        context.setdefault("run_digest", None)  # the evidence gate refuses results bound to no run
        context.update(code_sha256=code["sha256"], code=code, finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                       rootdir=str(config.rootpath),
                       args=list(config.invocation_params.args), markexpr=config.getoption("markexpr", "") or "",
                       python=sys.version.split()[0], pytest=pytest.__version__)
        doc = rq.results_document(registry(config), results, context=context,
                                  collection_errors=config.stash[_ERRORS], exitstatus=int(exitstatus))
        atomic_write_bytes(path, (json.dumps(doc, indent=2, sort_keys=False, allow_nan=False) + "\n").encode())
        config.stash[_WRITTEN] = (path, doc["summary"], results)

    def pytest_terminal_summary(self, terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
        written = config.stash.get(_WRITTEN, None)
        if not written:
            return
        path, summary, results = written
        tr = terminalreporter
        tr.write_sep("-", "safety requirements")
        for state, markup in (("verified", {"green": True}), ("failed", {"red": True}),
                              ("not verified", {"yellow": True})):
            ids = [rid for rid, r in results.items() if r.state == state]
            tr.write_line(f"{state:>13}: {summary[state]:2d}  {' '.join(ids)}", **markup)
        for rid, r in results.items():  # why each requirement is not verified, one line each
            if r.state != "verified":
                reason = " ".join(str(r.reason).split())
                tr.write_line(f"  {rid}: {r.state}: {reason[:400]}{'...' if len(reason) > 400 else ''}")
        tr.write_line(f"requirement results written to {path}")


def _skip_reason(report: Any) -> str:
    lr = report.longrepr
    if isinstance(lr, tuple) and len(lr) == 3:
        reason = str(lr[2])
    else:
        reason = str(lr or "")
    return re.sub(r"^Skipped: ", "", reason).strip()


def _crash_message(report: Any, limit: int = 2000) -> str:
    lr = report.longrepr
    crash = getattr(lr, "reprcrash", None)
    text = getattr(crash, "message", None) if crash is not None else None
    if not text:
        text = str(lr or "").strip().splitlines()[-1:] or [""]
        text = text[0] if isinstance(text, list) else text
    text = str(text).strip()
    return text if len(text) <= limit else text[: limit - 3] + "..."


def outcome_of(nodeid: str, reports: list[Any]) -> Any:
    """One TestOutcome from the setup / call / teardown reports of a test."""
    duration = float(sum(getattr(r, "duration", 0.0) for r in reports))
    for r in reports:
        if r.failed:
            kind = "failed" if r.when == "call" else "error"
            return rq.TestOutcome(nodeid, kind, duration, _crash_message(r))
    for r in reports:
        if r.skipped:
            if hasattr(r, "wasxfail"):
                return rq.TestOutcome(nodeid, "xfailed", duration, f"expected failure: {r.wasxfail}".rstrip(": "))
            return rq.TestOutcome(nodeid, "skipped", duration, _skip_reason(r))
    call = [r for r in reports if r.when == "call"]
    if call and call[0].passed:
        return rq.TestOutcome(nodeid, "xpassed" if hasattr(call[0], "wasxfail") else "passed", duration)
    return rq.TestOutcome(nodeid, "not run", duration)


def session_results(config: pytest.Config) -> dict[str, Any]:
    """Every requirement's RequirementResult for this session so far."""
    reg = registry(config)
    claims = dict(config.stash[_CLAIMS])
    deselected = config.stash[_DESELECTED]
    pairs = []
    seen = set()
    for nodeid, reports in config.stash[_PHASES].items():
        ids = claims.get(nodeid) or tuple(dict.fromkeys(
            rid for r in reports for k, v in r.user_properties if k == MARKER for rid in str(v).split(",") if rid))
        pairs.append((ids, outcome_of(nodeid, reports)))
        seen.add(nodeid)
    for nodeid, ids in claims.items():
        if nodeid in seen or not ids:
            continue
        outcome = "deselected" if nodeid in deselected else "not run"
        pairs.append((ids, rq.TestOutcome(nodeid, outcome, 0.0, "")))
    return rq.evaluate(reg, pairs)


def _report_path(config: pytest.Config) -> Path | None:
    given = _setting(config, "requirements_report", "uav_el_report")
    if given:
        return Path(given)
    markexpr = config.getoption("markexpr", "") or ""
    if re.search(rf"(?<!not )\b{MARKER}\b", markexpr):
        return config.rootpath / DEFAULT_REPORT
    return None
