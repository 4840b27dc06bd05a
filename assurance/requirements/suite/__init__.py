"""The requirement checks as pytest tests, shipped in the package: ``uav-el verify RUN --out DIR`` runs them (a thin
wrapper over pytest), and ``pytest --pyargs assurance.requirements.suite my_tests/ -m requirements --uav-el-run RUN``
runs them with a user's own requirement tests. The run binding and the fixtures they use (``campaign_run``,
``requirement_registry``) are the plugin's (``assurance.requirements.pytest_plugin``)."""

from __future__ import annotations

from pathlib import Path

SUITE_DIR = Path(__file__).resolve().parent
"""The folder of the packaged requirement tests (what ``uav-el verify`` hands to pytest)."""
