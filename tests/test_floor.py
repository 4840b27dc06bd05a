"""The floor under every monitor's unsafe landings (assurance.analysis.floor)."""

import numpy as np
import pandas as pd
import pytest

from assurance.analysis.floor import floor_markdown, monitor_floor


def _tables():
    """Five frames under one perturbation, two configurations each: a safe candidate (A), every candidate unsafe with
    the default area unsafe (B) or safe (D), no candidate with the default area unsafe (C), a faulted frame (E)."""
    frames = {"A": (1.0, [True, False]), "B": (1.5, [True, True]), "C": (1.0, []), "D": (0.2, [True]),
              "E": (1.0, [True])}
    images, candidates = [], []
    for monitor in ("m1", "m2"):
        for key, (h_default, unsafe) in frames.items():
            images.append({"perturbation": "fog", "severity": 3, "key": key, "monitor": monitor,
                           "fault": "boom" if key == "E" and monitor == "m2" else "", "h_default": h_default,
                           "candidates": len(unsafe), "h_top": 1.0 if unsafe else float("nan")})
            candidates += [{"perturbation": "fog", "severity": 3, "key": key, "monitor": monitor, "rank": k,
                            "true_unsafe": u, "true_hazard": 1.0 if u else 0.2} for k, u in enumerate(unsafe)]
    return pd.DataFrame(images), pd.DataFrame(candidates)


def test_the_floor_counts_frames_with_no_safe_way_out_and_leaves_faulted_frames_out():
    images, candidates = _tables()
    floor = monitor_floor(images, candidates)
    assert floor.to_dict("records") == [{"perturbation": "fog", "severity": 3, "images": 4, "no_candidate": 1,
                                         "all_unsafe": 2, "floor": 2, "perfect_g_rm": pytest.approx(0.4)}]
    assert "| fog (s3) | 4 | 1 | 2 | 2 (0.500) | +0.400 |" in floor_markdown(floor)
    assert monitor_floor(images.iloc[:0], candidates.iloc[:0]).empty


def test_without_true_hazards_the_most_a_monitor_can_add_is_unknown_not_nought():
    images, candidates = _tables()
    unknown = monitor_floor(images, candidates.drop(columns="true_hazard"))
    assert np.isnan(unknown["perfect_g_rm"].item()) and "| n/a |" in floor_markdown(unknown)


def test_no_configuration_of_a_campaign_lands_unsafely_less_often_than_the_floor(tiny_campaign):
    """On a real run: every configuration's unsafe landings are at least the floor, per perturbation, and
    ``uav-el table`` prints it."""
    from assurance.campaign import readouts

    run = tiny_campaign["run"]
    images, candidates = readouts.load_table(run, "images"), readouts.load_table(run, "candidates")
    floor = monitor_floor(images, candidates).set_index(["perturbation", "severity"])
    assert len(floor) == images.drop_duplicates(["perturbation", "severity"]).shape[0]
    unsafe = images.groupby(["perturbation", "severity", "monitor"])["decision_unsafe"].sum()
    for (pert, sev, _), n in unsafe.items():
        assert n >= floor.loc[(pert, sev), "floor"]
    assert np.all(floor["floor"] <= floor["images"])
    faulted = images.groupby(["perturbation", "severity", "key"])["fault"].transform(
        lambda f: (f.fillna("").astype(str) != "").any())
    judged = images[~faulted.astype(bool)]  # the frames the floor judges
    gain = (readouts.core_hazard(judged) - judged["h_decision"]).groupby(
        [judged["perturbation"], judged["severity"], judged["monitor"]]).mean()  # each configuration's G_RM
    for (pert, sev, _), g in gain.items():  # no monitor adds more than the lowest hazard on offer allows
        assert g <= floor.loc[(pert, sev), "perfect_g_rm"] + 1e-12


def test_the_evidence_names_the_floor_among_its_limitations_only_when_there_is_one():
    from assurance.evidence.sections import floor_limitation

    images, candidates = _tables()
    text = floor_limitation(monitor_floor(images, candidates))
    assert len(text) == 1 and "in 2 of the 4 frames judged (2 of 4 fog (s3))" in text[0]
    safe = candidates.assign(true_unsafe=False)
    assert floor_limitation(monitor_floor(images[images["key"] != "C"], safe)) == []
    assert floor_limitation(None) == []
    from assurance.evidence.sections import refused_frames

    refused = images.assign(reason="outside_odd: image_width 320 px not in [1920, 1920] px")
    assert refused_frames(refused) == refused.drop_duplicates(["perturbation", "severity", "key"]).shape[0]
    said = floor_limitation(monitor_floor(refused, candidates), refused_frames(refused))[0]
    assert "were refused before any landing (outside the declared domain or by the frame gate)" in said
    assert refused_frames(images) == 0
