"""The import graph of ``el`` and ``assurance`` has no cycle, ``el`` never imports ``assurance``, and each package
imports only downwards through its layers (``LAYERS``, ``EL_LAYERS``).

What counts as an edge A -> B (module A imports module B):

- every ``import`` / ``from ... import`` statement in A, at module level *and* inside functions: a
  function-level import only defers the cycle to call time, it does not remove it;
- ``importlib.import_module("x.y")`` with a literal name, or an f-string with a literal prefix
  (``f"assurance.cli.{name}"``: an edge to every module under that prefix);
- not the imports under ``if TYPE_CHECKING:`` (never executed);
- not the implicit import of a module's parent packages (``import el.monitors.lhd`` runs
  ``el/monitors/__init__.py``): a package's ``__init__`` re-exporting its submodules is the usual
  layout and Python resolves it, so only explicit imports of the package itself count.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("el", "assurance")


def module_files(root: Path = ROOT) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``) for every module of the packages."""
    out: dict[str, tuple[Path, bool]] = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def _is_type_checking(node: ast.If) -> bool:
    return ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")


def _import_nodes(tree: ast.AST) -> list[ast.AST]:
    """Import statements and ``importlib.import_module`` calls anywhere but under ``if TYPE_CHECKING``."""
    found: list[ast.AST] = []
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _is_type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        elif isinstance(node, ast.Call) and ast.unparse(node.func) in ("importlib.import_module", "import_module"):
            found.append(node)
        stack.extend(ast.iter_child_nodes(node))
    return found


def _imported_names(module: str, is_package: bool, node: ast.AST) -> list[str]:
    """Dotted names a node imports; a trailing ``*`` stands for every module under a prefix."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = module.split(".") if is_package else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            package = ".".join(base + ([node.module] if node.module else []))
        else:
            package = node.module or ""
        return [package] + [f"{package}.{alias.name}" for alias in node.names]
    arg = node.args[0] if isinstance(node, ast.Call) and node.args else None
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return [arg.value]
    if isinstance(arg, ast.JoinedStr) and arg.values and isinstance(arg.values[0], ast.Constant):
        return [f"{arg.values[0].value}*"]
    return []


def _resolve(name: str, modules: dict[str, tuple[Path, bool]]) -> set[str]:
    """The project modules a dotted name denotes (its longest prefix that is one, or all under a ``*``)."""
    if name.endswith("*"):
        return {m for m in modules if m.startswith(name[:-1])}
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return {name} if name else set()


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the project modules it imports (see the module docstring for what counts)."""
    modules = module_files(root)
    graph: dict[str, set[str]] = {}
    for module, (path, is_package) in modules.items():
        targets: set[str] = set()
        for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            names = _imported_names(module, is_package, node)
            if isinstance(node, ast.ImportFrom) and len(names) > 1:
                # ``from pkg import sub`` imports the submodule when there is one, else a name of ``pkg``
                subs = [n for n in names[1:] if n in modules]
                names = subs + ([names[0]] if len(subs) < len(names) - 1 else [])
            for name in names:
                targets |= _resolve(name, modules)
        graph[module] = targets - {module}
    return graph


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (a path ``a -> ... -> a``) per strongly connected component of more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's algorithm (recursion depth = the longest import chain)
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_cycle_through(component, graph) for component in components]


def _cycle_through(component: list[str], graph: dict[str, set[str]]) -> list[str]:
    """The shortest cycle from the component's first module back to it (breadth first)."""
    start, members = component[0], set(component)
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & members):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if w not in previous:
                    previous[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no cycle through {start}")  # pragma: no cover (a component always has one)


def test_cycle_finder_reports_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert find_cycles(graph) == [["a", "b", "c", "a"]]


def test_graph_sees_function_level_and_dynamic_imports(tmp_path: Path) -> None:
    (tmp_path / "el").mkdir()
    (tmp_path / "assurance" / "cli").mkdir(parents=True)
    for init in ("el", "assurance"):
        (tmp_path / init / "__init__.py").write_text("")
    (tmp_path / "el" / "a.py").write_text("def f():\n    from el import b\n")
    (tmp_path / "el" / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import el.a\n")
    (tmp_path / "assurance" / "cli" / "__init__.py").write_text(
        "import importlib\nimportlib.import_module(f'assurance.cli.{x}')\n")
    (tmp_path / "assurance" / "cli" / "run.py").write_text("def f():\n    from . import main\n")
    graph = import_graph(tmp_path)
    assert graph["el.a"] == {"el.b"} and graph["el.b"] == set()
    assert graph["assurance.cli"] == {"assurance.cli.run"}
    assert find_cycles(graph) == [["assurance.cli", "assurance.cli.run", "assurance.cli"]]


def test_no_import_cycles() -> None:
    cycles = find_cycles(import_graph())
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_flight_code_never_imports_the_harness() -> None:
    bad = sorted(f"{m} -> {t}" for m, targets in import_graph().items() if m.split(".")[0] == "el"
                 for t in targets if t.split(".")[0] == "assurance")
    assert not bad, "el imports assurance:\n" + "\n".join(bad)


LAYERS = (
    ("base", ("(root)", "errors", "files", "paths", "progress", "workers", "bounded", "code_identity", "perturbations",
              "attest")),
    ("dataio", ("dataio",)),
    ("scenes", ("scenes",)),
    ("system", ("system",)),
    ("campaign", ("campaign",)),
    ("analysis", ("analysis",)),
    ("fitting", ("fitting",)),
    ("requirements", ("requirements",)),
    ("fault_injection", ("fault_injection",)),
    ("inservice", ("inservice",)),
    ("evidence", ("evidence",)),
    ("cli", ("cli", "__main__")),
)
"""The harness's layers, bottom first: a module imports only from its own layer's parts or from layers below
(imports inside functions included). The data on disk (UAVid layout, poses) below the synthetic scenes; the system
file below the campaign that runs it; analysis of readouts above the campaign; the fitting tools above both;
requirements above what they judge; fault injection above what it exercises; in-service evidence (flight logs against
a run) above the requirements it names; the report above the requirements and the in-service evidence it shows;
the command line on top."""


EL_LAYERS = (
    ("base", ("base",)),
    ("classes", ("classes",)),
    ("geometry", ("geometry",)),
    ("landing", ("landing",)),
    ("segmentation", ("segmentation",)),
    ("monitors", ("monitors",)),
    ("flight", ("flight", "(root)")),
)
"""The flight code's layers, bottom first, under the same rule: the base (errors, bounded file reading, hashing,
the deadline, the decision record) below the label sets; the camera geometry, declared domain and discs above them;
the core model (candidates, regions, ranking) above the geometry; the network seam above both; the monitors (and the
walk that asks them) above the network whose patches they segment; the kernel, the pipeline and its flight log on
top, with the package's public face (``el/__init__``, which loads them on first use). Each layer is one folder of
``el`` (docs/architecture.md section 1.1): the layout is the contract."""

PACKAGE_LAYERS = {"assurance": LAYERS, "el": EL_LAYERS}


def layer_of(module: str) -> int | None:
    """The layer index of a module of ``el`` or ``assurance`` in its package's layers (None: neither package)."""
    parts = module.split(".")
    layers = PACKAGE_LAYERS.get(parts[0])
    if layers is None:
        return None
    part = parts[1] if len(parts) > 1 else "(root)"
    for i, (_, members) in enumerate(layers):
        if part in members:
            return i
    raise AssertionError(f"{module}: its part {part!r} of {parts[0]} is in no layer of its package's layers")


def test_every_module_has_a_layer() -> None:
    for module in import_graph():
        layer_of(module)


def test_each_package_imports_only_downwards() -> None:
    """The harness and the flight code each import only from their own layer or below (``el`` never imports
    ``assurance`` at all: above)."""
    bad = []
    for module, targets in import_graph().items():
        mine = layer_of(module)
        if mine is None:
            continue
        layers = PACKAGE_LAYERS[module.split(".")[0]]
        for target in targets:
            theirs = layer_of(target) if target.split(".")[0] == module.split(".")[0] else None
            if theirs is not None and theirs > mine:
                bad.append(f"{module} ({layers[mine][0]}) -> {target} ({layers[theirs][0]})")
    assert not bad, "imports against the layer order:\n" + "\n".join(sorted(bad))


def test_a_layer_violation_is_reported(tmp_path: Path) -> None:
    (tmp_path / "el").mkdir()
    (tmp_path / "el" / "__init__.py").write_text("")
    for part in ("dataio", "cli"):
        (tmp_path / "assurance" / part).mkdir(parents=True)
        (tmp_path / "assurance" / part / "__init__.py").write_text("")
    (tmp_path / "assurance" / "__init__.py").write_text("")
    (tmp_path / "assurance" / "dataio" / "io.py").write_text("def f():\n    from assurance.cli import x\n")
    graph = import_graph(tmp_path)
    assert "assurance.cli" in graph["assurance.dataio.io"]
    assert layer_of("assurance.dataio.io") < layer_of("assurance.cli")
    assert layer_of("el.geometry.camera") < layer_of("el.landing.core") < layer_of("el.monitors.lhd") \
        < layer_of("el.flight.pipeline")
