"""Size limits of the code under ``el`` and ``assurance``: no module over 500 lines, no function over 80.

A module counts its physical lines; a function (or method, or nested function) counts from its ``def`` line to
its last line, decorators excluded and docstring included (``end_lineno - lineno + 1`` of the ``def`` node).
Long code is split into named helpers or smaller modules instead.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("el", "assurance")
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80


def _sources() -> list[tuple[str, str]]:
    """(path relative to the repository, source text) of every module of the packages."""
    return [(path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8"))
            for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))]


def _long_functions(rel: str, source: str) -> list[str]:
    """``path:line name (n lines)`` for each function or method of a module longer than the limit."""
    out = []
    for node in ast.walk(ast.parse(source, filename=rel)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            n = node.end_lineno - node.lineno + 1
            if n > MAX_FUNCTION_LINES:
                out.append(f"{rel}:{node.lineno} {node.name} ({n} lines)")
    return out


def test_the_packages_have_modules() -> None:
    rels = [rel for rel, _ in _sources()]
    assert "el/__init__.py" in rels and "assurance/__init__.py" in rels


def test_no_module_over_500_lines() -> None:
    offenders = [f"{rel} ({n} lines)" for rel, source in _sources()
                 if (n := len(source.splitlines())) > MAX_MODULE_LINES]
    assert not offenders, f"modules over {MAX_MODULE_LINES} lines:\n" + "\n".join(offenders)


def test_no_function_over_80_lines() -> None:
    offenders = [line for rel, source in _sources() for line in _long_functions(rel, source)]
    assert not offenders, f"functions over {MAX_FUNCTION_LINES} lines:\n" + "\n".join(offenders)
