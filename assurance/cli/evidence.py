"""``uav-el evidence``: the evidence report of a campaign run, and the gate on the requirement states."""

from __future__ import annotations

import argparse

WORK = "assurance.cli.evidence_run"
"""Its work, imported only when it runs (heavy imports at its top: --help stays light)."""

HELP = ("write the evidence report (HTML, PDF, JSON) of a campaign run; exit 1 when a requirement failed, "
        "when the requirement results are not bound to this run, code and registry or contradict the run, or "
        "when a waiver expired, or when a requirement is left not verified for want of evidence (one left undecided "
        "only by the run's size, as the registry's size_limited allows on a small run, fails it with --strict "
        "only); exit 4 for a damaged run")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--run", required=True, help="campaign run folder (uav-el campaign --out)")
    p.add_argument("--out", default="reports", help="output folder (default: reports/)")
    p.add_argument("--requirements", metavar="JSON",
                   help="requirement results of `uav-el verify RUN --out OUT` (default: "
                        "OUT/requirements.json if present; without one every requirement is 'not verified')")
    p.add_argument("--baseline", metavar="RUN0", help="an earlier run: adds a 'what changed' section")
    p.add_argument("--baseline-requirements", metavar="JSON", help="the baseline's requirement results")
    p.add_argument("--registry", metavar="YAML", help="requirement registry (default: assurance/requirements.yaml)")
    p.add_argument("--targets", metavar="JSON", help="requirement targets overriding the registry's parameters (a "
                   "JSON object, the file given to pytest --uav-el-targets); the results must use the same")
    p.add_argument("--waivers", help="accepted deviations: a failed requirement listed there does not fail the "
                   "gate; ignored with --strict (default: the system file's [waivers] file; for the shipped system, "
                   "the shipped assurance/waivers.yaml; a system file without [waivers]: none)")
    p.add_argument("--strict", action="store_true",
                   help="also exit 1 when a requirement is left undecided by the run's size alone (size_limited, on a "
                        "small run), and when the PDF cannot be written; ignores waivers")
    p.add_argument("--no-pdf", action="store_true", help="write the HTML and JSON only")
    p.add_argument("--trusted-keys", metavar="PEM|DIR",
                   help="public keys whose signatures are accepted (a PEM file, or a folder of *.pem/*.pub); default: "
                        "$UAV_EL_TRUSTED_KEYS, else the local signing key's own (uav-el keys)")
    p.add_argument("--templates", metavar="DIR",
                   help="section templates replacing the packaged ones file by file (copy a section_*.html.j2 or "
                        "auditor_*.html.j2 of evidence_templates/ into DIR and edit it); rendered with time and "
                        "memory limits and cleaned to an allow-list of markup; the first page, layout and "
                        "stylesheet are always the toolkit's, and the first page names the folder with its hash "
                        "(default: the packaged templates only)")
    p.add_argument("--template-seconds", type=float, default=None, metavar="S",
                   help="wall-time limit of the supplied templates' rendering, per template (default 60); past it "
                        "the template is refused (exit 2)")
    p.add_argument("--system-templates", action="store_true",
                   help="use the system file's [report] templates as --templates (an applicant's convenience; an "
                        "auditor's report takes none unasked)")
    p.add_argument("--accept-deviation", metavar="NAME=VALUE", action="append", default=[],
                   help="accept a deviation from the certification basis (the packaged registry's) at the value the "
                        "system sets, e.g. unsafe_landing_bound=0.06 or class:road=safe (a class's value is its "
                        "state, safe or forbidden; numbers compare numerically; repeat for several); the report's "
                        "first page records it with both values. A deviation not accepted, or accepted at another "
                        "value, fails the gate; a plain NAME is refused")
    p.add_argument("--benchmark", metavar="DIR", help="a uav-el benchmark --out folder: adds its monitor comparison "
                   "as a section (re-derived from its CSV tables; never moves the gate)")
    p.add_argument("--in-service", metavar="DIR", help="a uav-el in-service --out folder: adds its signed SPI verdicts "
                   "and the claims a breach undermines as a section (never moves the gate)")
    p.add_argument("--boot", type=int, default=2000, help="bootstrap resamples of the results table (default 2000)")
