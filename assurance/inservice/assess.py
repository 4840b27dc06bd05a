"""One in-service assessment: flight logs against the certification run of their system, judged by its SPIs.

:func:`assess` is what ``uav-el in-service`` calls: the run verified (its shards, and its signed campaign statement
against trusted keys), the logs read against the run's identity (a log of another system refused in one line), the
comparisons and the SPIs of the run's system file, the report written and signed. The system file is the run's own
(its signed manifest records it), so the SPIs judged are the ones certified, not ones loosened afterwards.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from assurance.campaign import readouts
from assurance.campaign.attestation import UnattestedRunError, check_run_attestation
from assurance.campaign.integrity import verify_run
from assurance.code_identity import code_identity
from assurance.inservice import compare as cmp
from assurance.inservice import report, spi
from assurance.inservice.reader import read_logs
from assurance.requirements import load_registry
from el.base.hashing import sha256_file


@dataclass(frozen=True)
class Assessment:
    """What :func:`assess` wrote and found: the document, its files and statement, and the breaches."""

    doc: dict[str, Any]
    json_path: Path
    html_path: Path
    attestation: Path | None

    @property
    def breaches(self) -> list[str]:
        return list(self.doc["breaches"])


def _titles() -> dict[str, str]:
    """Requirement id -> title, from the shipped registry (the claims a breach names)."""
    return {r.id: r.title for r in load_registry()}


def _candidate_threshold(cert: cmp.Certified, run: Path) -> float | None:
    """The monitor's threshold the run recorded for the flown configuration (None when not one value)."""
    cands = readouts.load_table(run, "candidates")
    if "threshold" not in cands:
        return None
    values = cands.loc[cands["monitor"] == cert.monitor, "threshold"].dropna().unique()
    return float(values[0]) if len(values) == 1 else None


def assess(logs: Sequence[str | Path], run: str | Path, out: str | Path, *, system: Any, trusted: Mapping[str, Any],
           key: Any = None) -> Assessment:
    """Compare ``logs`` with ``run`` and write the report into ``out`` (see the module docstring); ``system``: the
    run's system file (``assurance.system.SystemFile``), whose ``[in_service]`` declares the SPIs; ``trusted``: the
    keys the run's statement must verify against; ``key``: the signing key (None: not signed).

    Raises ``DamagedRunError`` (exit 4) for a damaged or unattested run, ``OtherSystemError`` or
    ``RunMismatchError`` (one line, exit 2) for logs of another system or configuration."""
    run = Path(run)
    check = verify_run(run).raise_if_damaged()
    attested = check_run_attestation(run, trusted)
    if not attested.ok:
        raise UnattestedRunError(run, attested.problems)
    manifest = readouts.read_manifest(run)
    identity = cmp.run_identity(manifest)
    odd = system.odd()
    summary = read_logs(logs, expected=identity, odd=odd)
    if not summary.records:
        raise ValueError(f"{', '.join(map(str, logs))}: no readable decision in the flight log(s) "
                         f"({summary.damaged} damaged line(s))")
    monitor = cmp.flown_monitor(summary, manifest, run)
    settings = spi.settings_of(system.in_service(), system.targets())
    cert = cmp.certified(run, monitor, budget_s=system.time_budget_s)
    comparison = cmp.compare(summary, cert, conf=float(settings["confidence"]), odd=odd)
    results = spi.judge(comparison, settings)
    envelope = run / "campaign.dsse.json"
    run_info = {"path": str(run.resolve()), "digest": check.digest, "signed_by": attested.keyid,
                "campaign_attestation_sha256": sha256_file(envelope) if envelope.is_file() else None}
    judgement = report.Judgement(comparison=comparison, spis=results, settings=settings,
                                 undermined=spi.undermined(results, _titles()))
    doc = report.document(run=run_info, identity=identity, monitor=monitor, system=system.label, summary=summary,
                          judgement=judgement)
    figures = report.plots(doc, summary, cert.gate_scores, cert.candidate_scores,
                           candidate_threshold=_candidate_threshold(cert, run))
    json_path, html_path = report.write_report(out, doc, figures)
    signed = None
    if key is not None:
        pins = {"run_digest": check.digest, "campaign_attestation_sha256": run_info["campaign_attestation_sha256"],
                **identity, "monitor": monitor, "logs": [{k: f[k] for k in ("path", "sha256", "records", "damaged")}
                                                         for f in summary.files],
                "verdict": doc["verdict"], "breaches": doc["breaches"], "code": code_identity()}
        signed = report.sign(out, key, pins)
    return Assessment(doc, json_path, html_path, signed)


__all__ = ["Assessment", "assess"]
