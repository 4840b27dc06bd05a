"""The in-service report: ``in-service.json`` (the document), ``in-service.html`` (a page with its plots) and
``in-service.dsse.json`` (their signed statement, as ``uav-el verify`` signs the requirement results).

The document holds finished numbers only (the comparisons, the SPIs and their verdicts, the claims a breach
undermines, the logs read by SHA-256, the timeline); the page's template computes nothing. The statement is an
in-toto statement (kind ``in-service``) whose subjects are both files and whose predicate pins the run (its digest
and its campaign statement), the system's identity, the logs and the verdict: ``check_attestation`` verifies it
against trusted keys and the files as they are now (the evidence report's "In service" section reads nothing else).
"""

from __future__ import annotations

import base64
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from assurance.analysis.intervals import clopper_pearson_interval
from assurance.attest import AttestationError
from assurance.attest.dsse import read_envelope, write_envelope
from assurance.attest.statement import make_statement, open_statement, sign_statement, subject_problems
from assurance.files import atomic_write_text
from assurance.inservice.reader import LogSummary, Window
from el.base.hashing import sha256_file

FORMAT = "uav-el-in-service/1"
JSON_NAME, HTML_NAME, ATTESTATION = "in-service.json", "in-service.html", "in-service.dsse.json"
KIND = "in-service"
TEMPLATE = "in-service.html.j2"
"""The page's template (``assurance/data/``)."""
MAX_DOCUMENT_BYTES = 16 << 20
COLOURS = {"service": "#d64545", "run": "#2a7ab9", "bound": "#444444"}


PLOT_WINDOWS, MIN_WINDOW = 24, 10
"""The timeline shown: at most PLOT_WINDOWS windows of at least MIN_WINDOW decisions each (the reader's, merged)."""


def _coarse(windows: Sequence[Window]) -> list[Window]:
    """Consecutive windows merged until each holds enough decisions for a rate with a useful interval."""
    total = sum(w.n for w in windows)
    per = max(MIN_WINDOW, math.ceil(total / PLOT_WINDOWS))
    out: list[Window] = []
    for w in windows:
        if out and out[-1].n < per:
            out[-1] = out[-1].merge(w)
        else:
            out.append(w)
    if len(out) > 1 and out[-1].n < per:  # a short last window joins the one before it
        out[-2:] = [out[-2].merge(out[-1])]
    return out


def timeline(summary: LogSummary, conf: float) -> list[dict[str, Any]]:
    """The logs' windows (``reader.Timeline``, merged to at least ``MIN_WINDOW`` decisions each) with each rate and
    its two-sided exact interval at ``conf``."""
    out = []
    for w in _coarse(summary.timeline.windows):
        row: dict[str, Any] = {"start_s": w.start_s, "end_s": w.end_s, "n": w.n}
        for name, k in (("refusal", w.refusals), ("default", w.defaults), ("overrun", w.overruns)):
            lo, hi = clopper_pearson_interval(int(k), int(w.n), conf)
            row[name] = {"k": k, "rate": k / w.n if w.n else None, "ci": [_finite(lo), _finite(hi)]}
        out.append(row)
    return out


def _finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


@dataclass(frozen=True, kw_only=True)
class Judgement:
    """What the comparison of the logs with the run found: the measurements compared (``comparison``,
    ``assurance.inservice.compare.compare``), each SPI's result (``spis``), the ``[in_service]`` settings they were
    judged with, and the claims a breach undermines (``undermined``)."""

    comparison: Mapping[str, Any]
    spis: Sequence[Any]
    settings: Mapping[str, Any]
    undermined: Sequence[Mapping[str, Any]]


def document(*, run: Mapping[str, Any], identity: Mapping[str, Any], monitor: str, system: str, summary: LogSummary,
             judgement: Judgement) -> dict[str, Any]:
    """The JSON document of an in-service comparison (see the module docstring): the run (``run``: where, its digest,
    its signer; ``identity``: the system and configuration it certified), the flown ``monitor``, the ``system``
    file's label, the logs read (``summary``) and what the comparison found (``judgement``)."""
    comparison, spis, settings, undermined = (judgement.comparison, judgement.spis, judgement.settings,
                                              judgement.undermined)
    breached = [r.name for r in spis if r.verdict == "breach"]
    times = [w.start_s for w in summary.timeline.windows] + [w.end_s for w in summary.timeline.windows]
    return {
        "format": FORMAT, "system": system, "run": dict(run), "identity": dict(identity), "monitor": monitor,
        "logs": list(summary.files), "records": summary.records, "damaged": summary.damaged,
        "damaged_lines": list(summary.damaged_lines), "log_checks": summary.findings.to_dict(),
        "period": {"first_s": min(times) if times else None, "last_s": max(times) if times else None},
        "settings": dict(settings), "comparison": dict(comparison), "spis": [r.to_dict() for r in spis],
        "breaches": breached, "undermined": list(undermined), "verdict": "breach" if breached else "no breach",
        "timeline": timeline(summary, float(settings.get("confidence", 0.95))),
    }


def _data_uri(fig: Any) -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def histogram(service: Sequence[float], run: Sequence[float], *, title: str, threshold: float | None) -> str | None:
    """Score histograms in service and in the run (densities, shared bins), the threshold marked; a PNG data URI,
    None without scores on either side."""
    from matplotlib.figure import Figure

    s, r = np.asarray(service, float), np.asarray(run, float)
    if not len(s) and not len(r):
        return None
    both = np.concatenate([s, r])
    bins = np.histogram_bin_edges(both, bins=30)
    fig = Figure(figsize=(6.4, 2.8))
    ax = fig.add_subplot()
    for values, name in ((r, "certification run (clean test)"), (s, "service")):
        if len(values):
            ax.hist(values, bins=bins, density=True, alpha=0.55, label=f"{name}, n = {len(values)}",
                    color=COLOURS["run" if name.startswith("cert") else "service"])
    if threshold is not None and math.isfinite(threshold):
        ax.axvline(threshold, color=COLOURS["bound"], linestyle="--", label=f"threshold {threshold:.4g}")
    ax.set_title(title, fontsize=10)
    ax.set_ylabel("density")
    ax.legend(fontsize=8)
    return _data_uri(fig)


def rates_over_time(rows: Sequence[Mapping[str, Any]], bounds: Mapping[str, float | None]) -> str | None:
    """The refusal and default rates per window of the timeline with their intervals, and each SPI's bound."""
    from matplotlib.figure import Figure

    if not rows:
        return None
    fig = Figure(figsize=(6.4, 3.0))
    ax = fig.add_subplot()
    x = np.arange(len(rows))
    for offset, (name, colour) in zip((-0.12, 0.12), (("refusal", COLOURS["service"]), ("default", COLOURS["run"])),
                                      strict=True):
        rate = np.array([r[name]["rate"] if r[name]["rate"] is not None else np.nan for r in rows], float)
        lo = np.array([r[name]["ci"][0] if r[name]["ci"][0] is not None else np.nan for r in rows], float)
        hi = np.array([r[name]["ci"][1] if r[name]["ci"][1] is not None else np.nan for r in rows], float)
        err = np.nan_to_num(np.vstack([rate - lo, hi - rate]), nan=0.0)
        ax.errorbar(x + offset, rate, yerr=np.maximum(err, 0), fmt="o", ms=3, color=colour,
                    label=f"{name} rate (two-sided interval)")
        bound = bounds.get(name)
        if bound is not None:
            ax.axhline(bound, color=colour, linestyle="--", linewidth=1, label=f"max {name} rate {bound:g}")
    ax.set_xticks(x)
    ax.set_xlabel(f"windows of about {rows[0]['n']} decisions, in time order")
    ax.set_ylabel("rate")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=7, ncol=2)
    return _data_uri(fig)


def plots(doc: Mapping[str, Any], summary: LogSummary, run_gate: Sequence[float], run_scores: Sequence[float],
          *, candidate_threshold: float | None) -> dict[str, str | None]:
    """The page's figures as PNG data URIs (None where there is nothing to draw)."""
    thresholds = doc["comparison"]["frame_gate"]["thresholds"]
    settings = doc["settings"]
    return {"gate": histogram(summary.gate_scores.values, run_gate, title="Frame-gate score",
                              threshold=thresholds[0] if len(thresholds) == 1 else None),
            "monitor": histogram(summary.candidate_scores.values, run_scores,
                                 title="Monitor score of judged candidates", threshold=candidate_threshold),
            "rates": rates_over_time(doc["timeline"], {"refusal": settings.get("max_refusal_rate"),
                                                       "default": settings.get("max_default_rate")})}


def render_html(doc: Mapping[str, Any], figures: Mapping[str, str | None]) -> str:
    """The page (``assurance/data/in-service.html.j2``, autoescaped): the document's numbers and the figures."""
    from importlib import resources

    import jinja2

    text = resources.files("assurance").joinpath(f"data/{TEMPLATE}").read_text(encoding="utf-8")
    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    return env.from_string(text).render(doc=doc, figures=figures)


def write_report(out: str | Path, doc: Mapping[str, Any], figures: Mapping[str, str | None]) -> tuple[Path, Path]:
    """Write ``in-service.json`` and ``in-service.html`` into ``out`` (atomically); their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    json_path, html_path = out / JSON_NAME, out / HTML_NAME
    atomic_write_text(json_path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    atomic_write_text(html_path, render_html(doc, figures))
    return json_path, html_path


def _subjects(out: Path) -> dict[str, str]:
    return {name: sha256_file(out / name) for name in (JSON_NAME, HTML_NAME) if (out / name).is_file()}


def sign(out: str | Path, key: Any, pins: Mapping[str, Any]) -> Path:
    """Sign both files of ``out`` with ``pins`` (the run, the identity, the logs, the verdict); the statement's path."""
    out = Path(out)
    path = out / ATTESTATION
    write_envelope(path, sign_statement(make_statement(_subjects(out), KIND, dict(pins)), key))
    return path


def check_attestation(out: str | Path, trusted: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """(the signed predicate with ``signed_by``, problems): the statement must verify against ``trusted`` and sign
    both files as they are now."""
    out = Path(out)
    path = out / ATTESTATION
    try:
        stmt, keyid = open_statement(read_envelope(path), trusted, KIND, where=str(path))
    except AttestationError as exc:
        return {}, [f"{exc}: an in-service report is evidence only as `uav-el in-service` wrote and signed it"]
    problems = [f"{out}: {p}" for p in subject_problems(stmt, _subjects(out))]
    return dict(stmt["predicate"], signed_by=keyid), problems


__all__ = ["ATTESTATION", "FORMAT", "HTML_NAME", "JSON_NAME", "check_attestation", "document", "plots",
           "render_html", "sign", "timeline", "write_report"]
