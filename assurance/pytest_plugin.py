"""pytest plugin: the ``requirements`` marker that ties tests to safety requirements."""

from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "requirements(*ids): the test verifies these safety requirements (e.g. 'EL-R01')",
    )
