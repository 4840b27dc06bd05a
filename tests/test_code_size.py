"""Size limits of the code under ``el`` and ``assurance``: no module over 500 lines, no function over 80, no function
taking more than 8 parameters, and few imports of the project's own modules inside functions (issue 58: each left
says why, ``# deferred: <reason>``).

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
MAX_PARAMETERS = 8
MAX_FUNCTION_IMPORTS = 60  # issue 58: the project's own imports inside functions, each deferring a heavy dependency
"""Parameters a function takes, ``self``/``cls`` not counted (``*args`` and ``**kwargs`` count one each); more travel
together as a record (configuration as data: ``ReportOptions``, ``Execution``, ...)."""


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


def _parameters(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = node.args
    n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
    return n - 1 if a.args and a.args[0].arg in ("self", "cls") else n


def _function_imports(rel: str, source: str) -> list[tuple[str, str]]:
    """(``path:line``, the import's source line) of each import of ``el``/``assurance`` (or a relative one) inside
    a function of a module."""
    lines, out, seen = source.splitlines(), [], set()
    for node in ast.walk(ast.parse(source, filename=rel)):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        for sub in ast.walk(node):
            if isinstance(sub, ast.ImportFrom):
                ours = sub.level > 0 or (sub.module or "").split(".")[0] in PACKAGES
            elif isinstance(sub, ast.Import):
                ours = any(alias.name.split(".")[0] in PACKAGES for alias in sub.names)
            else:
                continue
            if ours and sub.lineno not in seen:
                seen.add(sub.lineno)
                out.append((f"{rel}:{sub.lineno}", lines[sub.end_lineno - 1]))
    return out


def test_no_function_takes_more_than_8_parameters() -> None:
    offenders = [f"{rel}:{node.lineno} {node.name} ({_parameters(node)})" for rel, source in _sources()
                 for node in ast.walk(ast.parse(source, filename=rel))
                 if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and _parameters(node) > MAX_PARAMETERS]
    assert not offenders, f"functions taking more than {MAX_PARAMETERS} parameters:\n" + "\n".join(offenders)


def test_a_function_level_import_says_why() -> None:
    """An import of the project's own modules inside a function defers a heavy dependency or breaks a cycle, and
    says which (``# deferred: ...`` on its line)."""
    silent = [where for rel, source in _sources() for where, line in _function_imports(rel, source)
              if "# deferred:" not in line]
    assert not silent, "function-level imports without '# deferred: <reason>':\n" + "\n".join(silent)


def test_function_level_imports_stay_few() -> None:
    """Imports at the top: a command's heavy work lives in its own ``*_run`` module, imported when it runs."""
    found = [where for rel, source in _sources() for where, _ in _function_imports(rel, source)]
    assert len(found) <= MAX_FUNCTION_IMPORTS, f"{len(found)} function-level imports:\n" + "\n".join(found)


def test_parameters_and_imports_are_counted() -> None:
    source = "def f(a, b, *c, d, **e):\n    from el.base import errors  # deferred: x\n    import json\n"
    node = ast.parse(source).body[0]
    assert _parameters(node) == 5
    assert _function_imports("m.py", source) == [("m.py:2", "    from el.base import errors  # deferred: x")]
