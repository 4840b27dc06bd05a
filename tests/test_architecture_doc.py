"""docs/architecture.md names only what exists: repository paths, ``el.``/``assurance.`` names, ``uav-el``
sub-commands, its diagram and its own section anchors.

What counts as a name (so that the page must be written precisely):

- a repository path: ``el/...``, ``assurance/...``, ``tests/...``, ``benchmarks/...`` or ``docs/...`` inside a
  backticked span, a fenced code block or a link target; a trailing ``/`` names a folder. A placeholder
  stops the path (``el/monitors/<name>.py`` checks the folder ``el/monitors/``);
- a dotted name starting with ``el.`` or ``assurance.`` anywhere in the page: its longest importable prefix
  is the module, the rest are attributes, each of which must exist;
- ``uav-el WORD`` anywhere in the page: WORD must be a sub-command (``assurance.cli.COMMANDS``);
- a link target relative to ``docs/`` (the diagram PNG among them) and an in-page anchor ``#sN-M``.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from assurance.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"

_FENCE = re.compile(r"^ {0,3}```[^\n]*\n(.*?)^ {0,3}```", re.S | re.M)
_SPAN = re.compile(r"`([^`]+)`")  # outside fences backticks pair up; a span may wrap a line
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)\)")
_PATH = re.compile(r"(?<![\w./-])((?:el|assurance|tests|benchmarks|docs)/[\w./-]*)")
_DOTTED = re.compile(r"(?<![\w./-])((?:el|assurance)(?:\.[A-Za-z_]\w*)+)")
_COMMAND = re.compile(r"(?<![\w-])uav-el[ \t]+([a-z][a-z-]*)")
_ANCHOR_DEF = re.compile(r'<a id="([^"]+)"></a>')


def code_texts(text: str) -> list[str]:
    """The page's fenced code blocks and, outside them, its backticked spans and link targets."""
    blocks = _FENCE.findall(text)
    rest = _FENCE.sub("", text)
    return blocks + _SPAN.findall(rest) + _LINK.findall(rest)


def named_paths(text: str) -> set[str]:
    """Repository paths the page names (trailing sentence punctuation dropped; a trailing ``/`` kept)."""
    return {m.rstrip(".,;:") for chunk in code_texts(text) for m in _PATH.findall(chunk)}


def missing_paths(text: str, root: Path = ROOT) -> list[str]:
    """Named paths that do not exist (a trailing ``/`` must name a folder)."""
    return sorted(p for p in named_paths(text)
                  if not (root / p).exists() or (p.endswith("/") and not (root / p).is_dir()))


def dotted_names(text: str) -> set[str]:
    return {m.rstrip(".") for m in _DOTTED.findall(text)}


def resolve(name: str) -> object:
    """The object a dotted name denotes: the longest importable prefix as module, the rest as attributes.

    Raises ModuleNotFoundError / AttributeError when the name does not exist; an import that fails for
    another reason (a missing dependency inside the module) is raised as it is."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        module_name = ".".join(parts[:i])
        try:
            obj = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and (module_name == exc.name or module_name.startswith(exc.name + ".")):
                continue  # this prefix is not a module: try a shorter one
            raise
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(f"no importable prefix in {name!r}")


def unresolved_names(text: str) -> list[str]:
    bad = []
    for name in sorted(dotted_names(text)):
        try:
            resolve(name)
        except (ImportError, AttributeError) as exc:
            bad.append(f"{name}: {type(exc).__name__}: {exc}")
    return bad


def named_commands(text: str) -> set[str]:
    return set(_COMMAND.findall(text))


def missing_links(text: str, base: Path = DOC.parent) -> list[str]:
    """Relative link targets (images included) that do not exist, and in-page anchors that are not defined."""
    anchors = set(_ANCHOR_DEF.findall(text))
    bad = []
    for target in _LINK.findall(_FENCE.sub("", text)):
        if re.match(r"^[a-z]+:", target):
            continue  # http(s), mailto: not checked here
        path, _, anchor = target.partition("#")
        if path and not (base / path).exists():
            bad.append(target)
        elif not path and anchor not in anchors:
            bad.append(target)
    return bad


@pytest.fixture(scope="module")
def doc() -> str:
    return DOC.read_text(encoding="utf-8")


def test_every_repository_path_the_page_names_exists(doc: str) -> None:
    assert len(named_paths(doc)) > 50, "the path pattern found almost nothing: is it still right?"
    assert missing_paths(doc) == []


def test_every_el_and_assurance_name_the_page_names_resolves(doc: str) -> None:
    assert len(dotted_names(doc)) > 30, "the name pattern found almost nothing: is it still right?"
    assert unresolved_names(doc) == []


def test_every_uav_el_command_the_page_names_is_a_sub_command(doc: str) -> None:
    named = named_commands(doc)
    assert len(named) > 5
    assert sorted(named - set(COMMANDS)) == []


def test_the_diagram_is_in_the_page_and_its_png_exists(doc: str) -> None:
    images = [t for t in _IMAGE.findall(doc) if t.endswith(".png")]
    assert images, "the page links no PNG diagram"
    assert all((DOC.parent / t).is_file() for t in images), images
    assert "```dot\n" in doc, "the diagram's DOT source is not in the page"


def test_links_and_anchors_resolve(doc: str) -> None:
    assert missing_links(doc) == []


def test_the_checks_catch_a_wrong_name(doc: str) -> None:
    """Each check fails on a renamed path, module, attribute, sub-command or image."""
    assert missing_paths("see `el/no_such_module.py` and `el/monitors/`") == ["el/no_such_module.py"]
    assert missing_paths("`el/monitors/walk.py/`") == ["el/monitors/walk.py/"]  # a file named as a folder
    assert unresolved_names("`el.monitors.walk.walk_candidates` and `el.monitors.walk.no_such_function`")[0].startswith(
        "el.monitors.walk.no_such_function: AttributeError")
    assert unresolved_names("`el.no_such_module.thing`")[0].startswith("el.no_such_module.thing: AttributeError")
    assert unresolved_names("`assurance.cli.COMMANDS`") == []
    assert named_commands("`uav-el land` and `uav-el lnad`") - set(COMMANDS) == {"lnad"}
    assert missing_links("![d](no_such.png) [x](#s99)") == ["no_such.png", "#s99"]
