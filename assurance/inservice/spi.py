"""Safety performance indicators (SPIs): what the system file's ``[in_service]`` declares, judged on the logs.

Each SPI is a claim about service that the certificate assumed (UL 4600's SPIs; AMLAS stage 6, monitoring the deployed
model). A rate SPI ("the frame gate refuses at most 10% of frames") is judged as the requirements judge a rate bound
(``assurance.analysis.intervals.decide_rate_bound``, one-sided Clopper-Pearson at the declared confidence): ``breach``
when the lower bound is above the target (the logs already show it broken, whatever their size), ``pass`` when the
upper bound is at most the target, ``undecided`` in between (too few decisions to tell). A drift SPI is a two-sample
test at ``drift_alpha``: ``breach`` when p < alpha, ``pass`` otherwise, ``undecided`` with too few scores. An SPI the
file does not declare is ``not declared`` (never judged). A breach names the claims of the safety argument it
undermines: the requirement ids and their GSN goals (``assurance.evidence.argument``: ``G-<requirement>``, the AMLAS
stage goals ``G-AMLAS<n>``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from assurance.analysis.intervals import BOUND_MET, BOUND_MISSED, decide_rate_bound

PASS, BREACH, UNDECIDED, NOT_DECLARED = "pass", "breach", "undecided", "not declared"
DEFAULT_DRIFT_ALPHA = 0.01
"""The drift tests' level when ``[in_service] drift_alpha`` is not set."""
DEFAULT_CONFIDENCE = 0.95
"""The rate bounds' one-sided confidence when neither ``[in_service] confidence`` nor ``[targets] confidence`` is set
(the registry's ``confidence``)."""


@dataclass(frozen=True)
class SpiDefinition:
    """One SPI: the ``[in_service]`` key it is declared by, what it measures (a path into the comparison), what it
    states, the claims a breach undermines (requirement ids, GSN goal ids) and why."""

    name: str
    key: str
    measure: str
    statement: str
    requirements: tuple[str, ...]
    nodes: tuple[str, ...]
    why: str


SPIS: tuple[SpiDefinition, ...] = (
    SpiDefinition("refusal_rate", "max_refusal_rate", "frame_gate.refusal",
                  "the frame gate refuses at most {target:.3g} of the decisions",
                  ("EL-R09", "EL-R10"), ("G-EL-R09", "G-EL-R10", "G-AMLAS6"),
                  "the safety gain and the unsafe-landing bound were measured at the run's refusal rate; frames the "
                  "gate refuses more often than certified are frames the evidence does not cover"),
    SpiDefinition("default_rate", "max_default_rate", "default",
                  "the default action is taken in at most {target:.3g} of the decisions",
                  ("EL-R09",), ("G-EL-R09",),
                  "'safer than the default action' (G* > 0) rests on landing as often as the campaign did"),
    SpiDefinition("overrun_rate", "max_overrun_rate", "overrun",
                  "at most {target:.3g} of the decisions overrun their deadline",
                  ("EL-R07", "EL-R13"), ("G-EL-R07", "G-EL-R13"),
                  "the decision within the time budget, and the monitor's overhead within it, were shown on the "
                  "campaign's machine, not on this one"),
    SpiDefinition("frame_gate_drift", "drift_alpha", "frame_gate.drift",
                  "the frame gate's scores in service come from the distribution of the run's clean test frames "
                  "(two-sample test at alpha = {target:.3g})",
                  ("EL-R09", "EL-R10"), ("G-EL-R09", "G-EL-R10", "G-AMLAS3"),
                  "the test scenes stand for the frames flown: the campaign's figures hold for frames like them"),
    SpiDefinition("monitor_score_drift", "drift_alpha", "monitor.drift",
                  "the runtime monitor's candidate scores in service come from the distribution of the run's clean "
                  "test candidates (two-sample test at alpha = {target:.3g})",
                  ("EL-R10", "EL-R16"), ("G-EL-R10", "G-EL-R16", "G-AMLAS6"),
                  "the monitor's calibrated miss rate and the unsafe-landing bound assume candidates like the test "
                  "split's"),
)
"""The SPIs, in report order (configuration as data: one entry per SPI)."""
AMLAS_GOALS = {"G-AMLAS3": "AMLAS stage 3: data management assurance is sufficient",
               "G-AMLAS6": "AMLAS stage 6: model deployment assurance is sufficient"}
"""The AMLAS stage goals an SPI names (``assurance.evidence.argument.AMLAS_STAGES``), by GSN id."""


@dataclass(frozen=True)
class SpiResult:
    """One SPI judged: its verdict, the numbers behind it and, for a breach, the claims it undermines."""

    name: str
    key: str
    statement: str
    target: float | None
    verdict: str
    evidence: str
    requirements: tuple[str, ...]
    nodes: tuple[str, ...]
    why: str

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "requirements": list(self.requirements), "nodes": list(self.nodes)}


def settings_of(section: Mapping[str, Any] | None, targets: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The SPI settings in effect: ``[in_service]`` as declared, with ``drift_alpha`` and ``confidence`` defaulted
    (``confidence``: ``[targets] confidence`` when the section sets none) and ``min_decisions`` 1."""
    out = dict(section or {})
    out.setdefault("drift_alpha", DEFAULT_DRIFT_ALPHA)
    out.setdefault("confidence", (targets or {}).get("confidence", DEFAULT_CONFIDENCE))
    out.setdefault("min_decisions", 1)
    return out


def _at(comparison: Mapping[str, Any], path: str) -> Mapping[str, Any]:
    value: Any = comparison
    for part in path.split("."):
        value = value[part]
    return value


def _rate(measured: Mapping[str, Any], target: float, conf: float, min_n: int) -> tuple[str, str]:
    """A rate SPI's verdict and evidence. Decisions whose records are missing (``unlogged``, sequence gaps) are
    judged both ways: a pass must hold were every one of them an event, a breach were none."""
    side = measured["service"]
    k, n, gaps = int(side["k"]), int(side["n"]), int(side.get("unlogged", 0))
    bound = decide_rate_bound(k, n, target, conf, min_n=min_n)
    if gaps:
        worst = decide_rate_bound(k + gaps, n + gaps, target, conf, min_n=min_n)
        best = decide_rate_bound(k, n + gaps, target, conf, min_n=min_n)
        verdict = BREACH if best.verdict == BOUND_MISSED else PASS if worst.verdict == BOUND_MET else UNDECIDED
    else:
        verdict = BREACH if bound.verdict == BOUND_MISSED else PASS if bound.verdict == BOUND_MET else UNDECIDED
    run = measured["run"]
    run_text = f"; the run: {run['k']} of {run['n']}" if run["n"] else ""
    gap_text = (f"; {gaps} decision(s) not logged, judged both as events and as none (a pass holds either way, a "
                "breach either way, else undecided)") if gaps else ""
    return verdict, f"{bound.text()}, target {target:g}{run_text}{gap_text}"


def _drift(measured: Mapping[str, Any], alpha: float) -> tuple[str, str]:
    if measured["p_value"] is None:
        return UNDECIDED, f"{measured['n_service']} scores in service, {measured['n_run']} in the run: " \
                          f"{measured.get('why_not', 'not tested')}"
    p, stat = measured["p_value"], measured["statistic"]
    text = (f"KS D = {stat:.3f}, p = {p:.3g} ({measured['n_service']} scores in service, {measured['n_run']} in the "
            f"run; medians {measured['median_service']:.4g} and {measured['median_run']:.4g})")
    return (BREACH if p < alpha else PASS), text


def judge(comparison: Mapping[str, Any], settings: Mapping[str, Any]) -> list[SpiResult]:
    """Every SPI of :data:`SPIS` judged on ``comparison`` (``assurance.inservice.compare.compare``) with ``settings``
    (:func:`settings_of`)."""
    conf, min_n = float(settings["confidence"]), int(settings["min_decisions"])
    out = []
    for d in SPIS:
        target = settings.get(d.key)
        if target is None:
            verdict, evidence = NOT_DECLARED, f"[in_service] {d.key} is not set"
            statement = d.statement.replace("{target:.3g}", "(not declared)")
        else:
            measured = _at(comparison, d.measure)
            verdict, evidence = (_drift(measured, float(target)) if d.key == "drift_alpha"
                                 else _rate(measured, float(target), conf, min_n))
            statement = d.statement.format(target=float(target))
        out.append(SpiResult(d.name, d.key, statement, None if target is None else float(target), verdict, evidence,
                             d.requirements, d.nodes, d.why))
    return out


def breaches(results: list[SpiResult]) -> list[SpiResult]:
    return [r for r in results if r.verdict == BREACH]


def undermined(results: list[SpiResult], titles: Mapping[str, str] | None = None) -> list[dict[str, Any]]:
    """The claims the breaches undermine, each once: GSN goal id, requirement id (None for an AMLAS stage goal), its
    title where known, and the SPIs that undermine it."""
    found: dict[str, dict[str, Any]] = {}
    names = {**AMLAS_GOALS, **(titles or {})}
    for r in breaches(results):
        for node in r.nodes:
            req = node[2:] if node.startswith("G-EL-") else None
            entry = found.setdefault(node, {"node": node, "requirement": req, "title": names.get(req or node, ""),
                                            "spis": []})
            entry["spis"].append(r.name)
    return list(found.values())


__all__ = ["BREACH", "DEFAULT_DRIFT_ALPHA", "NOT_DECLARED", "PASS", "SPIS", "UNDECIDED", "SpiDefinition", "SpiResult",
           "breaches", "judge", "settings_of", "undermined"]
