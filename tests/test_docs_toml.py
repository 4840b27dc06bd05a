"""Every ```toml block of README.md and docs/*.md parses (a new user copies them: issue 51 met a walkthrough that did
not), and every block of a system file (a top-level key the system file's schema knows) is valid against that
schema, so no documented key, type or value is one the loader refuses."""

import re
import tomllib
from pathlib import Path

import pytest

from assurance.system.loader import schema, validate

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```toml[^\n]*\n(.*?)^```", re.S | re.M)


def toml_blocks() -> list[tuple[str, str]]:
    """``(file:line, text)`` of every ```toml fenced block of README.md and docs/*.md."""
    blocks = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            blocks.append((f"{path.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}", m.group(1)))
    return blocks


BLOCKS = toml_blocks()


def test_the_docs_have_toml_blocks_to_check():
    where = [w for w, _ in BLOCKS]
    assert len(BLOCKS) >= 4, where
    assert any(w.startswith("docs/certify.md:") for w in where), where  # the walkthrough's system file


@pytest.mark.parametrize(("where", "text"), BLOCKS, ids=[w for w, _ in BLOCKS])
def test_toml_block_parses_and_a_system_file_is_valid(where, text):
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        pytest.fail(f"{where}: not valid TOML: {exc}")
    if set(doc) & set(schema()["properties"]):  # a system file, or a part of one
        validate(doc, label=where)
