"""The certification basis: a system's targets looser than the packaged registry's, or a label set that declares a
class of a forbidden hazard category safe, are deviations the auditor must accept by name; the report's texts are
about the system assessed (its camera, pose, forbidden classes), never the shipped one unless it is assessed."""

import pytest

from assurance.requirements.basis import deviations, label_deviations
from assurance.requirements.registry import load_registry
from assurance.requirements.system_facts import facts_of, shipped_facts
from el.classes.labels import UAVID, LabelSet, load_label_set


def _road_safe() -> LabelSet:
    d = UAVID.to_dict()
    road = next(c for c in d["classes"] if c["name"] == "road")
    road.update(forbidden=False, hazard_score=0.0)
    return LabelSet.from_dict(d)


def test_the_packaged_label_sets_declare_every_category_and_keep_the_basis():
    params = load_registry().parameters
    must, accepted = params["forbidden_categories"], params["safe_unknown_accepted"]
    assert set(must) == {"road", "vehicle", "building", "water", "obstacle"}
    for labels in (UAVID, load_label_set("uavid"), load_label_set("semantic_drone")):
        assert all(c.category for c in labels.classes), labels.name
        assert [d.name for d in label_deviations(labels, must, accepted) if not d.accepted] == []
    assert load_label_set("uavid") == UAVID  # categories are data about the classes, not a different set


def test_uavids_clutter_is_a_deviation_the_basis_itself_accepts_for_that_set_only():
    """A safe class of the category unknown is a deviation, even declared ``unknown``; the registry accepts UAVid's
    clutter by the set's content SHA-256, in the open (page 1 lists it), and nothing else."""
    params = load_registry().parameters
    must, accepted = params["forbidden_categories"], params["safe_unknown_accepted"]
    (clutter,) = label_deviations(UAVID, must, accepted)
    assert clutter.name == "class:clutter" and clutter.accepted and "safe_unknown_accepted" in clutter.text()
    assert "declared safe with category unknown" in clutter.text()
    (bare,) = label_deviations(UAVID, must)  # without the registry's entry: not accepted
    assert not bare.accepted and "--accept-deviation class:clutter=safe" in bare.text()
    d = UAVID.to_dict()
    d["name"] = "uavid-copy"  # another set (another content hash) with a class of the same name: not accepted
    (copy,) = label_deviations(LabelSet.from_dict(d), must, accepted)
    assert copy.name == "class:clutter" and not copy.accepted
    assert [x.name for x in deviations({}, labels=UAVID) if not x.accepted] == []


def test_a_safe_class_in_a_well_known_forbidden_colour_is_a_deviation():
    """A safe 'meadow' painted in road's colour while road keeps an unused one: ``colour:meadow``, accepted only at
    its colour."""
    d = UAVID.to_dict()
    next(c for c in d["classes"] if c["name"] == "road")["rgb"] = [1, 2, 3]
    d["classes"].append({"id": 8, "name": "meadow", "rgb": [128, 64, 128], "forbidden": False, "hazard_score": 0.0,
                         "category": "vegetation"})
    found = {x.name: x for x in deviations({}, labels=LabelSet.from_dict(d))}
    colour = found["colour:meadow"]
    assert not colour.accepted and "road (uavid)" in colour.system and "paved-area (semantic_drone)" in colour.system
    assert "--accept-deviation colour:meadow=128,64,128" in colour.text()
    again = deviations({}, ["colour:meadow=128,64,128", "class:clutter=safe"], labels=LabelSet.from_dict(d))
    assert all(x.accepted for x in again)
    assert not next(x for x in deviations({}, ["colour:meadow=1,2,3"], labels=LabelSet.from_dict(d))
                    if x.name == "colour:meadow").accepted


def test_looser_targets_and_a_road_declared_safe_are_deviations():
    found = deviations({"unsafe_landing_bound": 0.999, "confidence": 0.5, "min_images_per_perturbation": 1,
                        "radius_m": 3.0}, labels=_road_safe())
    names = [d.name for d in found]
    assert names == ["min_images_per_perturbation", "unsafe_landing_bound", "confidence", "class:clutter", "class:road"]
    text = {d.name: d.text() for d in found}
    assert "0.999" in text["unsafe_landing_bound"] and "0.05" in text["unsafe_landing_bound"]
    assert "not accepted" in text["class:road"] and "--accept-deviation class:road=safe" in text["class:road"]
    assert [d.name for d in deviations({"unsafe_landing_bound": 0.01, "confidence": 0.99}, labels=UAVID)
            if not d.accepted] == []  # stricter: none


def test_a_deviation_is_accepted_only_by_its_name_and_value():
    found = deviations({"unsafe_landing_bound": 0.1}, ["unsafe_landing_bound=0.1"], labels=UAVID)
    assert [(d.name, d.accepted) for d in found] == [("unsafe_landing_bound", True), ("class:clutter", True)]
    with pytest.raises(ValueError, match="does not deviate from the basis on it"):
        deviations({}, ["confidence=0.5"], labels=UAVID)
    with pytest.raises(ValueError, match="NAME=VALUE"):  # a plain name binds no value: refused
        deviations({"unsafe_landing_bound": 0.1}, ["unsafe_landing_bound"], labels=UAVID)


def test_a_safe_class_without_a_category_cannot_be_checked():
    d = UAVID.to_dict()
    d["classes"][5].pop("category", None)
    found = label_deviations(LabelSet.from_dict(d), ["road"])
    assert [x.name for x in found] == ["class:clutter", "class:low_vegetation"] and "without one" in found[1].system


def test_an_unknown_category_is_refused():
    d = UAVID.to_dict()
    d["classes"][0]["category"] = "lava"
    with pytest.raises(ValueError, match="category 'lava' is not one of"):
        LabelSet.from_dict(d)


def test_the_registry_texts_are_about_the_system_assessed(tmp_path):
    from assurance.system.find import load_system
    from assurance.system.system import System

    shipped = load_registry()
    assert "phantom4" in shipped.operating_domain["camera"] and "oblique view" in shipped.operating_domain["camera"]
    assert "road" in shipped["EL-R01"].text and shipped.facts == shipped_facts()
    path = tmp_path / "uav-el.toml"
    path.write_text('[system]\nname = "nadir"\n[camera]\nname = "nadir-cam"\nsensor_width_mm = 23.5\nfocal_mm = 16.0\n'
                    'height_m = 20.0\npitch_deg = 90.0\n[labels]\npreset = "semantic_drone"\n')
    facts = facts_of(System.build(load_system(path)))
    reg = shipped.for_system(facts)
    assert "nadir-cam" in reg.operating_domain["camera"] and "nadir view" in reg.operating_domain["camera"]
    assert "height 20 m, pitch 90 degrees" in reg.operating_domain["pose"]
    assert "ground below the UAV" in reg.operating_domain["ground"]
    assert "paved-area" in reg["EL-R01"].text and "road, car" not in reg["EL-R10"].text
    assert reg.parameters == shipped.parameters  # the texts change, the targets do not


@pytest.mark.parametrize("name,category", [("tarmac", "road"), ("lane", "road"), ("car_park", "road"),
                                           ("Stra\u00dfe", "road"), ("voiture", "vehicle"), ("automobile", "vehicle"),
                                           ("b\u00e2timent", "building"), ("wasser", "water"), ("fence", "obstacle"),
                                           ("power_lines", "obstacle")])
def test_synonyms_other_languages_and_obstacles_declared_safe_are_deviations(name, category):
    """Issue 57: the review's synonyms (25 of 37 once flew as safe) carry their pinned category, and an obstacle is
    no ground known to be safe; declared safe as vegetation, each is a deviation naming the pinned category."""
    d = UAVID.to_dict()
    d["classes"].append({"id": 8, "name": name, "rgb": [1, 2, 3], "forbidden": False, "hazard_score": 0.0,
                         "category": "vegetation"})
    found = {x.name: x for x in deviations({}, labels=LabelSet.from_dict(d))}
    dev = found[f"class:{name}"]
    assert not dev.accepted and f"category {category}, pinned for the name" in dev.text()


def test_the_basis_accepted_classes_are_gate_policy_a_registry_may_only_narrow():
    """``safe_unknown_accepted`` is the registry's (pinned with it): no targets file sets it, and a registry given on
    the command line that accepts one more class is weaker than the system's."""
    from assurance.requirements.targets import GATE_POLICY, TargetError, validate_targets
    from assurance.requirements.weakening import parameter_weakenings

    params = load_registry().parameters
    assert "safe_unknown_accepted" in GATE_POLICY
    with pytest.raises(TargetError, match="the gate's policy is the registry's"):
        validate_targets({"safe_unknown_accepted": ["x:misc"]}, params)
    wider = {**params, "safe_unknown_accepted": [*params["safe_unknown_accepted"], "0" * 64 + ":misc"]}
    assert any("safe_unknown_accepted" in w for w in parameter_weakenings(params, wider))
    assert not any("safe_unknown_accepted" in w for w in parameter_weakenings(params, {**params,
                                                                                   "safe_unknown_accepted": []}))
