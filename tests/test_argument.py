"""The safety argument: generated from the registry, the hazard log and the results; its structural check, its gsn2x
YAML round trip, a failed / waived / not-verified requirement shown as such, and its drawing."""

from __future__ import annotations

import dataclasses

import pytest

from assurance import requirements as rq
from assurance.evidence.argument import ArgumentInputs, Node, build_argument, check_structure, from_yaml, to_yaml
from assurance.evidence.gsn_svg import argument_pages, page_svg
from assurance.evidence.hazards import load_hazards


@pytest.fixture(scope="module")
def parts():
    reg = rq.load_registry()
    return reg, load_hazards(None, reg)


def _results(reg, states):
    return {r.id: rq.RequirementResult(r.id, r.title, states.get(r.id, rq.VERIFIED), "because", []) for r in reg}


def _argument(reg, log, states=None, waivers=None):
    return build_argument(ArgumentInputs(registry=reg, hazards=log, results=_results(reg, states or {}),
                                         waivers=waivers or {}, checks={}, hashes={"requirements": "ab" * 32}))


def test_the_generated_argument_is_sound(parts):
    reg, log = parts
    nodes = _argument(*parts)
    assert check_structure(nodes) == []
    assert {f"G-{rid}" for rid in reg.ids} <= set(nodes)
    assert {f"G-{h.id}" for h in log.hazards} <= set(nodes)
    assert nodes["G-TOP"].supported_by == ["S-HAZ", "S-REQ", "S-ML"]


def test_a_requirement_missing_from_the_registry_breaks_the_structure_naming_its_goal(parts):
    reg, log = parts
    smaller = dataclasses.replace(reg, requirements={k: v for k, v in reg.requirements.items() if k != "EL-R05"})
    problems = check_structure(_argument(smaller, log))
    assert problems and all("G-EL-R05" in p for p in problems), problems


def test_failed_waived_and_not_verified_requirements_show_as_such(parts):
    reg, log = parts
    waiver = {"reason": "known issue", "owner": "alice", "expires": "2099-01-01"}
    nodes = _argument(reg, log, {"EL-R09": rq.FAILED, "EL-R10": rq.FAILED, "EL-R16": rq.NOT_VERIFIED},
                      {"EL-R10": waiver})
    assert check_structure(nodes) == []
    assert nodes["G-EL-R09"].cls == "failed" and "FAILED" in nodes["G-EL-R09"].text
    assert nodes["G-EL-R10"].cls == "waived" and nodes["G-EL-R10"].in_context_of == ["J-EL-R10"]
    assert "alice" in nodes["J-EL-R10"].text and "2099-01-01" in nodes["J-EL-R10"].text
    assert nodes["G-EL-R16"].undeveloped and not nodes["G-EL-R16"].supported_by
    assert nodes["G-EL-R01"].cls == "verified" and nodes["G-EL-R01"].supported_by == ["Sn-EL-R01-T"]
    assert nodes["G-H1"].cls == "failed"  # EL-R09 mitigates H1 and failed
    assert nodes["G-H7"].cls == "verified"


def test_the_gsn2x_yaml_round_trips(parts):
    nodes = _argument(*parts, {"EL-R16": rq.NOT_VERIFIED})
    text = to_yaml(nodes)
    back = from_yaml(text)
    assert back == nodes
    assert to_yaml(back) == text
    assert "undeveloped: true" in text and "supportedBy:" in text and "inContextOf:" in text


@pytest.mark.parametrize("nodes, says", [
    ([Node("G-1", "a", ["G-2"]), Node("G-2", "b", ["G-1"])], "cycle"),
    ([Node("G-1", "a", undeveloped=True), Node("G-2", "b", undeveloped=True)], "2 top goals"),
    ([Node("G-1", "a", ["Sn-1"]), Node("Sn-1", "b"), Node("Sn-1", "c")], "id used twice"),
    ([Node("G-1", "a", ["C-1"]), Node("C-1", "b")], "supportedBy C-1, a Context"),
    ([Node("G-1", "a")], "neither supported nor marked undeveloped"),
    ([Node("G-1", "a", ["S-1"]), Node("S-1", "b", ["G-2"]), Node("G-2", "b", ["S-1"])], "cycle"),
])
def test_the_structural_check_finds_each_fault(nodes, says):
    assert any(says in p for p in check_structure(nodes)), check_structure(nodes)


def test_the_drawing_has_a_top_page_and_one_per_strategy(parts):
    nodes = _argument(*parts, {"EL-R09": rq.FAILED})
    pages = argument_pages(nodes)
    assert [p["id"] for p in pages] == ["G-TOP", "S-HAZ", "S-REQ", "S-ML"]
    svg = page_svg(nodes, "S-REQ")
    assert svg.count("<rect") >= len(parts[0].ids) and "#c62828" in svg  # every requirement; the failed one red
    hazards = page_svg(nodes, "S-HAZ")
    assert "G-EL-R01 (see its page)" in hazards  # requirement goals are developed on their own page only
