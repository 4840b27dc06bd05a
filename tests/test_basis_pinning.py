"""Issue 50, the certification basis: everything that judged a run is pinned, the basis owns the hazard categories
of well-known class names, and ``--accept-deviation NAME=VALUE`` binds the value.

- The campaign's signed manifest records the content SHA-256 of the label set and of the class hierarchy it judged
  with; ``evidence`` recomputes both from the system it judges: a label set file put back under its name after the
  run (flown with road declared safe) is a gate problem naming the file.
- A well-known class name (road, car, building, person, water, ...) carries a pinned hazard category; a class
  declaring another is a deviation, a look-alike of one (or of another class) is refused, an unknown name without a
  category is ``unknown`` (a deviation when safe).
- An acceptance binds the value: numbers numerically, a class by its state (``class:road=safe``).
"""

from __future__ import annotations

import json
import shutil

import pytest
from conftest import TINY_WW, tiny_scene
from helpers import OracleSegmenter

from assurance.campaign import label_pin
from assurance.campaign.run import Execution
from assurance.requirements.basis import deviations, label_deviations, value_matches
from el.classes.class_names import class_key, pinned_category, skeleton
from el.classes.labels import UAVID, LabelSet, load_label_set

MUST = ("road", "vehicle", "building", "water")


def _uavid(**road: object) -> dict:
    d = UAVID.to_dict()
    next(c for c in d["classes"] if c["name"] == "road").update(road)
    return d


def _others(found: list) -> list:
    """The deviations but ``class:clutter`` (UAVid's clutter, safe and unknown: accepted by the basis only for the
    shipped set itself, so a deviation of every edited copy)."""
    return [d for d in found if d.name != "class:clutter"]


def _with_class(d: dict, name: str, **kw: object) -> dict:
    d["classes"].append({"id": len(d["classes"]), "name": name, "rgb": [1, 2, 3], "forbidden": False,
                         "hazard_score": 0.0, **kw})
    return d


# ------------------------------------------------------------------------------------------------
# Names: normalised, pinned, look-alikes refused
# ------------------------------------------------------------------------------------------------
def test_names_are_compared_normalised_and_well_known_ones_carry_a_pinned_category():
    assert class_key("Paved_Area") == class_key("paved-area") == class_key("PAVED  AREA") == "paved area"
    assert class_key("\uff52\uff4f\uff41\uff44") == "road"  # fullwidth letters: NFKC
    assert [pinned_category(n) for n in ("road", "Street", "paved-area", "static_car", "Cars", "roof", "human",
                                          "pedestrian", "swimming_pool", "lake")] == \
        ["road", "road", "road", "vehicle", "vehicle", "building", "person", "person", "water", "water"]
    assert pinned_category("low_vegetation") is None and pinned_category("clutter") is None
    assert skeleton("r\u043ead") == skeleton("ro\u200bad") == skeleton("r0ad") == skeleton("ro\u0301ad") == "road"


@pytest.mark.parametrize("name", ["r\u043ead", "ro\u0430d", "ro\u200bad", "r0ad", "ro\u0301ad", "buiIding",
                                  "\u0392uilding"])
def test_a_lookalike_of_a_well_known_name_is_refused(name):
    with pytest.raises(ValueError, match=r"label set 'uavid': class .* looks like the well-known class name"):
        LabelSet.from_dict(_with_class(UAVID.to_dict(), name, category="bare_ground"))


def test_two_classes_that_look_alike_are_refused():
    with pytest.raises(ValueError, match="'low_vegetation' and 'Low-Vegetation' look alike"):
        LabelSet.from_dict(_with_class(UAVID.to_dict(), "Low-Vegetation", category="vegetation"))
    with pytest.raises(ValueError, match="look alike"):
        LabelSet.from_dict(_with_class(UAVID.to_dict(), "c1utter", category="unknown"))


def test_the_shipped_label_sets_load_and_keep_the_basis():
    for source in ("uavid", "semantic_drone", "examples/my-drone/labels.yaml",
                   "examples/foreign-palette/labels.yaml"):
        labels = load_label_set(source)
        # the examples' "misc" (the UAVid clutter recoloured: safe, category unknown) is a deviation their auditor
        # sees; UAVid's own clutter is one the basis accepts (safe_unknown_accepted), Semantic Drone has none
        misc = ["class:misc"] if source.startswith("examples") else []
        assert [d.name for d in deviations({}, labels=labels) if not d.accepted] == misc, source


# ------------------------------------------------------------------------------------------------
# Categories: the basis's, not the set's
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("category", ["bare_ground", "unknown", None])
def test_road_declared_safe_is_a_deviation_whatever_category_it_declares(category):
    d = _uavid(forbidden=False, hazard_score=0.0, category=category)
    if category is None:
        next(c for c in d["classes"] if c["name"] == "road").pop("category")
    found = _others(label_deviations(LabelSet.from_dict(d), MUST))
    assert [x.name for x in found] == ["class:road"]
    assert "forbidden (category road, pinned for the name 'road')" in found[0].text()
    assert found[0].bound == "safe"


def test_a_redeclared_category_is_a_deviation_even_on_a_forbidden_class():
    found = _others(label_deviations(LabelSet.from_dict(_uavid(category="vehicle")), MUST))
    assert [(x.name, x.bound, x.relation) for x in found] == [("class:road", "forbidden", "differs from")]
    assert "forbidden, declared category vehicle differs from the basis's category road" in found[0].text()


def test_an_unknown_name_without_a_category_is_unknown_and_must_be_forbidden():
    safe = LabelSet.from_dict(_with_class(UAVID.to_dict(), "zone_7"))
    found = _others(label_deviations(safe, MUST))
    assert [x.name for x in found] == ["class:zone_7"] and "category unknown" in found[0].text()
    d = _with_class(UAVID.to_dict(), "zone_7")
    d["classes"][-1].update(forbidden=True, hazard_score=None)
    assert _others(label_deviations(LabelSet.from_dict(d), MUST)) == []  # forbidden: nothing to accept
    # issue 57: a declared "unknown" says nothing of the ground either: safe, it is a deviation the auditor sees
    (declared,) = _others(label_deviations(LabelSet.from_dict(_with_class(UAVID.to_dict(), "zone_7",
                                                                          category="unknown")), MUST))
    assert declared.name == "class:zone_7" and "declared safe with category unknown" in declared.text()


# ------------------------------------------------------------------------------------------------
# --accept-deviation NAME=VALUE
# ------------------------------------------------------------------------------------------------
def test_an_acceptance_binds_the_value():
    road_safe = LabelSet.from_dict(_uavid(forbidden=False, hazard_score=0.0, category="bare_ground"))
    found = {d.name: d for d in deviations({"unsafe_landing_bound": 0.06}, ["unsafe_landing_bound=0.060",
                                                                            "class:road=safe"], labels=road_safe)}
    assert found["unsafe_landing_bound"].accepted and found["class:road"].accepted
    text = found["unsafe_landing_bound"].text()
    assert "0.06 is looser than the basis's 0.05" in text and "accepted by the auditor" in text
    assert "(unsafe_landing_bound=0.060)" in text
    road = found["class:road"].to_dict()  # evidence.json: what was accepted, at which value
    assert (road["value"], road["accepted_value"], road["accepted"]) == ("safe", "safe", True)

    (loose,) = deviations({"unsafe_landing_bound": 0.999}, ["unsafe_landing_bound=0.06"])
    assert not loose.accepted and loose.given == "0.06"
    assert "the auditor accepted unsafe_landing_bound=0.06, but the system's value is 0.999" in loose.text()
    (road,) = _others(deviations({}, ["class:road=forbidden"], labels=road_safe))
    assert not road.accepted and "the system's value is safe" in road.text()


def test_a_plain_name_a_repeated_name_and_a_name_without_deviation_are_refused():
    with pytest.raises(ValueError, match=r"give the value you accept.*--accept-deviation unsafe_landing_bound=0.999"):
        deviations({"unsafe_landing_bound": 0.999}, ["unsafe_landing_bound"])
    with pytest.raises(ValueError, match="given twice"):
        deviations({"unsafe_landing_bound": 0.999}, ["unsafe_landing_bound=0.999", "unsafe_landing_bound=0.5"])
    with pytest.raises(ValueError, match="does not deviate from the basis on it"):
        deviations({"unsafe_landing_bound": 0.999}, ["confidence=0.5"])


def test_values_compare_by_kind():
    assert value_matches(0.06, "6e-2") and value_matches(10, "10.0") and not value_matches(0.06, "nan")
    assert value_matches("safe", "safe") and not value_matches("safe", "Safe")
    assert value_matches(["none", "fog"], "fog, none") and not value_matches(["none", "fog"], "none")
    assert value_matches({"height": 0.2, "pitch": 0.1}, '{"pitch": 0.10, "height": 0.2}')
    assert not value_matches({"height": 0.2}, "height=0.2")


# ------------------------------------------------------------------------------------------------
# The pin: recorded by the campaign, re-checked by the evidence
# ------------------------------------------------------------------------------------------------
class _LabelledOracle(OracleSegmenter):
    """The oracle network, judging with a given label set (the system's, as a class map would give it)."""

    def __init__(self, labels: LabelSet) -> None:
        super().__init__(TINY_WW)
        self.labels = labels


def _write_set(path, d: dict) -> None:
    path.write_text(json.dumps(d), encoding="utf-8")


@pytest.fixture(scope="module")
def pinned_run(tmp_path_factory):
    """A 2-image campaign flown with a label set file declaring road safe (``labels.json``, beside its system file),
    and the honest file to put back."""
    from assurance.campaign.run import CampaignConfig, Execution, run_campaign
    from assurance.dataio.uavid import write_sample
    from assurance.system import build as system_build
    from assurance.system import load_system
    from el.classes.labels import ids_to_colors

    root = tmp_path_factory.mktemp("pinned")
    for i in range(2):
        ids = tiny_scene(i)
        write_sample(root / "data", "seq00", f"{i:06d}", ids_to_colors(ids), ids, labels=UAVID)
    evil = _uavid(forbidden=False, hazard_score=0.0)
    _write_set(root / "labels.json", evil)
    (root / "uav-el.toml").write_text('[system]\nname = "pinned"\n[labels]\nfile = "labels.json"\n')
    system = load_system(root / "uav-el.toml")
    config = CampaignConfig(perturbations=("none",), monitors=("lhd",), images=2,
                            core=system_build.core_config(system, n_star=6, working_width=TINY_WW))
    summary = run_campaign(root / "data", root / "run", config,
                           segmenter=_LabelledOracle(LabelSet.from_dict(evil)), system=system,
                           execution=Execution(progress=False))
    assert summary["faults"] == []
    return {"root": root, "run": root / "run", "config": config, "evil": evil}


def _system_with(root, d: dict | None):
    from assurance.system import load_system

    if d is not None:
        _write_set(root / "labels.json", d)
    return load_system(root / "uav-el.toml")


def test_the_signed_manifest_pins_the_label_set_and_hierarchy(pinned_run):
    man = json.loads((pinned_run["run"] / "manifest.json").read_text())
    rec = man["labels"]
    assert rec["sha256"] == label_pin.label_set_sha256(LabelSet.from_dict(pinned_run["evil"]))
    assert rec["hierarchy_sha256"] and str(pinned_run["root"] / "labels.json") in rec["source"]
    from assurance.attest.keys import load_trusted_keys
    from assurance.campaign.attestation import check_run_attestation

    att = check_run_attestation(pinned_run["run"], load_trusted_keys(None))
    assert att.ok and att.predicate["label_set_sha256"] == rec["sha256"]
    # the built-in set is pinned too: its content, whatever file (none) it came from
    assert label_pin.label_record(UAVID)["sha256"] == label_pin.label_set_sha256(load_label_set("uavid"))


def test_a_label_set_put_back_after_the_run_is_a_gate_problem_naming_it(pinned_run, tmp_path):
    from assurance.evidence import generate

    root, run = pinned_run["root"], pinned_run["run"]
    same = _system_with(root, pinned_run["evil"])
    assert label_pin.label_problems(same, json.loads((run / "manifest.json").read_text()), None, run) == ([], [])
    honest = _system_with(root, UAVID.to_dict())
    try:
        report = generate(run, tmp_path / "rep", pdf=False, n_boot=20, system=honest)
    finally:
        _write_set(root / "labels.json", pinned_run["evil"])
    assert report.exit_code == 1
    problems = [p for p in report.problems if "changed since the run was made" in p]
    assert problems and problems[0].startswith(f"label set file {root / 'labels.json'}: changed since the run")
    assert not [p for p in report.problems if "deviation" in p]  # the honest file itself deviates from nothing


def test_a_changed_hierarchy_file_is_named(tmp_path):
    (tmp_path / "tree.yaml").write_text("root: any\nchildren: {any: [safe, unsafe], safe: [grass], unsafe: [road]}\n")
    (tmp_path / "labels.yaml").write_text(
        "name: fields\nhierarchy: tree.yaml\nclasses:\n"
        "  - {id: 0, name: grass, rgb: [0, 160, 0], forbidden: false, hazard_score: 0, category: vegetation}\n"
        "  - {id: 1, name: road, rgb: [128, 64, 128], forbidden: true}\n")
    (tmp_path / "uav-el.toml").write_text('[labels]\nfile = "labels.yaml"\n')
    from assurance.system import load_system

    man = {"labels": label_pin.label_record(load_label_set(tmp_path / "labels.yaml"),
                                            load_system(tmp_path / "uav-el.toml"))}
    (tmp_path / "tree.yaml").write_text("root: any\nchildren: {any: [grass, road]}\n")
    problems, _ = label_pin.label_problems(load_system(tmp_path / "uav-el.toml"), man, None, tmp_path)
    assert any(p.startswith(f"class hierarchy file {tmp_path / 'tree.yaml'}: changed since the run") for p in problems)


def test_a_run_without_the_pin_warns_unless_a_pinning_toolkit_signed_it(pinned_run, tmp_path):
    from assurance.attest.keys import load_signing_key, load_trusted_keys
    from assurance.campaign.attestation import sign_run
    from assurance.evidence import generate

    run = tmp_path / "run"
    shutil.copytree(pinned_run["run"], run)
    man = json.loads((run / "manifest.json").read_text())
    del man["labels"]
    (run / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True))
    system = _system_with(pinned_run["root"], None)
    problems, warnings = label_pin.label_problems(system, man, {"system_sha256": "x"}, run)  # an older statement
    assert problems == [] and "does not pin its label set" in warnings[0]
    sign_run(run, load_signing_key())  # signed by this toolkit: the statement carries the (empty) pin
    report = generate(run, tmp_path / "rep", pdf=False, n_boot=20, system=system, trusted=load_trusted_keys(None))
    assert any("does not pin its label set" in p for p in report.problems) and report.exit_code == 1


def test_a_run_is_not_resumed_with_another_label_set(pinned_run):
    from assurance.campaign.readouts import RunError
    from assurance.campaign.run import run_campaign

    honest = _system_with(pinned_run["root"], UAVID.to_dict())
    try:
        with pytest.raises(RunError, match="judged with another label set"):
            run_campaign(pinned_run["root"] / "data", pinned_run["run"], pinned_run["config"],
                         segmenter=OracleSegmenter(TINY_WW), system=honest, execution=Execution(progress=False))
    finally:
        _write_set(pinned_run["root"] / "labels.json", pinned_run["evil"])
