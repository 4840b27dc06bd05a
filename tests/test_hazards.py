"""The hazard log: valid against its schema and the registry, and every requirement traced to a hazard."""

from __future__ import annotations

import pytest

from assurance.evidence.hazards import HazardLogError, load_hazards, untraced
from assurance.requirements import load_registry


def test_every_requirement_mitigates_a_hazard():
    reg = load_registry()
    log = load_hazards(None, reg)
    assert len(log.hazards) >= 5
    assert untraced(log, reg) == []
    assert {r for h in log.hazards for r in h.mitigations} == set(reg.ids)


def test_a_requirement_no_hazard_names_is_reported(tmp_path):
    reg = load_registry()
    text = load_hazards(None, reg).path.read_text("utf-8").replace("EL-R05, ", "")
    (tmp_path / "h.yaml").write_text(text, "utf-8")
    assert untraced(load_hazards(tmp_path / "h.yaml", reg), reg) == ["EL-R05"]


@pytest.mark.parametrize("old, new, says", [
    ("severity: catastrophic", "severity: bad", "hazards.0.severity"),
    ("EL-R14, EL-R16]", "EL-R14, EL-R99]", "EL-R99 is not a requirement"),
    ("  - id: H2", "  - id: H1", "H1 appears twice"),
    ("    effect: collision", "    effekt: collision", "hazards.0"),
])
def test_a_broken_hazard_log_is_refused_naming_file_and_problem(tmp_path, old, new, says):
    reg = load_registry()
    text = load_hazards(None, reg).path.read_text("utf-8")
    assert old in text
    path = tmp_path / "hazards.yaml"
    path.write_text(text.replace(old, new, 1), "utf-8")
    with pytest.raises(HazardLogError) as err:
        load_hazards(path, reg)
    assert str(path) in str(err.value) and says in str(err.value)
