"""``uav-el verify``: the packaged requirement checks against a campaign run, a thin wrapper over pytest.

It runs ``assurance/requirements/suite`` (and a user's own requirement tests given with ``--tests``) with
``-m requirements`` bound to the run, and writes ``OUT/requirements.json`` and ``OUT/junit.xml``, which
``uav-el evidence --run RUN --out OUT`` reads. The same session is
``pytest --pyargs assurance.requirements.suite -m requirements --uav-el-run RUN --uav-el-report ...``."""

from __future__ import annotations

import argparse

WORK = "assurance.cli.verify_run"
"""Its work, imported only when it runs (heavy imports at its top: --help stays light)."""

HELP = ("run the packaged requirement checks (and your own requirement tests) against a campaign run: writes "
        "OUT/requirements.json and OUT/junit.xml for uav-el evidence; exit 1 when a requirement test failed")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN", help="campaign run folder (uav-el campaign --out)")
    p.add_argument("--out", default="reports", help="output folder (default: reports/)")
    p.add_argument("--tests", nargs="+", default=[], metavar="PATH",
                   help="your own tests marked @pytest.mark.requirements(...), run and bound with the packaged ones")
    p.add_argument("--registry", metavar="YAML", help="requirement registry (default: the shipped one)")
    p.add_argument("--targets", metavar="JSON", help="requirement targets overriding the registry's parameters")
    p.add_argument("-k", dest="keyword", metavar="EXPR", help="only the tests matching this pytest -k expression "
                   "(the requirements of the tests left out are then 'not verified')")
    p.add_argument("--waivers", metavar="YAML", help="the waivers the evidence step will apply, pinned in the signed "
                   "results (default: the system file's [waivers] file, else the shipped ones for the shipped system)")
    p.add_argument("--signing-key", metavar="PEM", help="Ed25519 key that signs the results (default: "
                   "$UAV_EL_SIGNING_KEY, else your key file; see uav-el keys)")
    p.add_argument("--trusted-keys", metavar="PEM|DIR", help="keys whose signature of the campaign run is accepted "
                   "(default: $UAV_EL_TRUSTED_KEYS, else your own key)")
