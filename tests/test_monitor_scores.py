"""Monitor scores: the paper's 21 configurations keep their verdicts, and each verdict follows the score."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from paper_cases import disc_mask, paper_cases

from el.monitors import PAPER_GRID, build_monitor

FROZEN = json.loads((Path(__file__).parent / "data" / "paper_verdicts.json").read_text())["verdicts"]


@pytest.fixture(scope="module")
def cases():
    return paper_cases()


def _features(spec: str, case):
    softmax, samples = case
    return samples if "mcd" in spec else softmax


@pytest.mark.parametrize("spec", PAPER_GRID)
def test_paper_specs_give_the_recorded_verdicts(spec, cases):
    assert len(FROZEN) == 21 and spec in FROZEN
    monitor, mask = build_monitor(spec), disc_mask()
    got = [monitor.check_scores(_features(spec, c), mask) for c in cases]
    assert [[v.accepted, v.reason] for v in got] == FROZEN[spec]
    assert 0 < sum(v.accepted for v in got) < len(got)  # the cases exercise both verdicts
