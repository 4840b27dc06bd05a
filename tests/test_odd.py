"""The declared operating domain: a frame whose pose or size is outside it ends in the default action
with reason outside_odd naming the dimension (a decision, not a fault); the system file declares it; campaign
readouts record it; EL-R17 fails when a landing is made outside the domain."""

from __future__ import annotations

import json

import pytest
from conftest import TINY_WW
from helpers import OracleSegmenter, bench_system, scene_ids, scene_image

from assurance.campaign.run import CampaignConfig, plan, run_task
from assurance.requirements.domain_checks import check_outside_domain
from assurance.system import default_system
from assurance.system.build import odd as system_odd
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.camera import Pose
from el.geometry.config import CoreConfig
from el.geometry.odd import OperatingDomain

WW = 128
DOMAIN = OperatingDomain(height_m=(40, 60), pitch_deg=(36, 54), image_width=(64, 7680), image_height=(36, 4320),
                         aspect=(1.5, 2.0), perturbations={"fog": 3})


def _decide(pose=None, image=None, odd=DOMAIN):
    cfg = PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd", odd=odd)
    return EmergencyLanding(cfg, segmenter=OracleSegmenter(WW)).decide(
        scene_image(scene_ids()) if image is None else image, pose=pose)


@pytest.mark.requirements("EL-R17")
@pytest.mark.parametrize("pose,dimension", [(Pose(height_m=120.0), "height 120 m not in [40, 60] m"),
                                            (Pose(height_m=20.0, pitch_deg=45.0), "height 20 m"),
                                            (Pose(pitch_deg=85.0), "pitch 85 deg not in [36, 54] deg")])
def test_a_pose_outside_the_range_is_refused_by_reason(pose, dimension):
    inside = _decide(Pose(height_m=50.0, pitch_deg=45.0))
    assert inside.action == "land" and not inside.reason.startswith("outside_odd")
    d = _decide(pose)
    assert d.action == "default" and d.reason.startswith("outside_odd: ") and dimension in d.reason
    assert d.input["pose"]["source"] == "frame" and d.config["odd"] == DOMAIN.to_dict()
    assert _decide(pose, odd=None).action == "land"  # no declaration: nothing refused


@pytest.mark.requirements("EL-R17")
def test_a_frame_size_or_aspect_outside_is_refused():
    square = scene_image(scene_ids())[:, :144]
    d = _decide(image=square)
    assert d.action == "default" and d.reason.startswith("outside_odd: aspect 1 not in [1.5, 2]")
    assert _decide(image=scene_image(scene_ids())[:34, :60]).reason.startswith("outside_odd: image_width 60 px")


def test_the_decision_schema_takes_the_reason():
    import jsonschema

    from el.base.decision import decision_schema

    d = _decide(Pose(height_m=120.0))
    jsonschema.validate(json.loads(d.to_json()), decision_schema())


def test_the_embedded_default_contains_the_release_and_test_frames():
    domain = system_odd(default_system())
    assert domain.outside(Pose(height_m=50.0, pitch_deg=45.0), (3840, 2160)) is None
    assert domain.outside(Pose(), (4096, 2160)) is None  # UAVid's other frame size
    for size in ((256, 144), (1024, 576), (1920, 1080), (7680, 4320)):  # no evidence at another size
        assert domain.outside(Pose(), size).startswith("outside_odd: image_width"), size
    assert domain.outside(Pose(), (3840, 2880)).startswith("outside_odd: image_height")
    assert domain.perturbations == {p: 3 for p in ("brightness", "fog", "motion_blur", "pixel_trap",
                                                   "shifted_pixels")}
    assert domain.covers("fog", 3) and not domain.covers("fog", 4) and domain.covers("none", 1)


def test_the_system_file_declares_the_domain(tmp_path):
    from assurance.system import load_system

    path = tmp_path / "uav-el.toml"
    path.write_text("[odd]\nheight_m = [10.0, 30.0]\n[camera]\nheight_m = 20.0\n")
    domain = system_odd(load_system(path))
    assert domain.height_m == (10.0, 30.0) and domain.pitch_deg == (36.0, 54.0)  # pitch: the default's
    path.write_text("[camera]\nheight_m = 80.0\nimage_width = 4000\nimage_height = 3000\n")
    moved = system_odd(load_system(path))  # a moved camera without [odd]: its nominal pose +-20%, its aspect +-5%
    assert moved.height_m == (64.0, 96.0) and moved.aspect[0] < 4 / 3 < moved.aspect[1]
    assert moved.image_width == (4000, 4000) and moved.image_height == (3000, 3000)  # and exactly its frame size
    for text, needle in (("[odd]\nheight_m = [10.0]\n", "odd.height_m"),
                         ("[odd]\nperturbations = { rain = 3 }\n", "unknown perturbation(s) rain"),
                         ("[odd]\nperturbations = { fog = 7 }\n", "odd.perturbations.fog"),
                         ("[odd]\npitch_deg = [60.0, 30.0]\n", "low <= high")):
        path.write_text(text)
        with pytest.raises(ValueError, match=needle.replace("(", r"\(").replace(")", r"\)")):
            system_odd(load_system(path))


@pytest.mark.requirements("EL-R17")
def test_the_requirement_fails_when_a_landing_is_made_out_of_domain(tiny_campaign):
    import pandas as pd

    base = dict(perturbations=("none", "fog"), monitors=("lhd",), core=CoreConfig(n_star=6, working_width=TINY_WW),
                images=3)
    high = OperatingDomain(height_m=(60, 120), pitch_deg=(0, 90), image_width=(1, 10_000),
                           image_height=(1, 10_000), aspect=(0.1, 10), perturbations={"fog": 3}).to_dict()

    def images(config):
        rows = [r for t in plan(tiny_campaign["data"], config)
                for r in run_task(t, config, OracleSegmenter(TINY_WW))["images"]]
        return pd.DataFrame(rows)

    blind = images(CampaignConfig(**base))  # a system that does not check its domain lands at 50 m
    assert (blind["action"] == "land").any()
    failed = check_outside_domain(blind, high)
    assert failed.status == "fail" and "landed although outside_odd: height 50 m" in failed.message()
    refused = images(CampaignConfig(**base, odd=high))  # the campaign decides as the flight code does
    assert (refused["action"] == "default").all() and refused["reason"].str.startswith("outside_odd: height").all()
    ok = check_outside_domain(refused, high)
    assert ok.status == "pass" and {(r["perturbation"], r["outside"], r["declared"]) for r in ok.rows} == \
        {("none", 3, "yes"), ("fog", 3, "yes")}
    assert check_outside_domain(refused, None).status == "insufficient"
    from assurance.evidence.domain_section import odd_rows

    man = {"config": {"odd": high, "core": {"pose": {"height_m": 50.0, "pitch_deg": 45.0}}}}
    rows = {r["name"]: r for r in odd_rows(man, refused, {"height": 0.2, "pitch": 0.2})}
    assert rows["Height"]["declared"] == "60 to 120 m"
    assert "6 evaluated frames (3 images x 2 perturbation scenarios) at 50 m (0 inside)" in rows["Height"]["evidence"]
    assert rows["Frames outside"]["evidence"] == "none: 3, fog: 3"
    assert rows["Perturbation fog"]["evidence"].endswith(": NOT covered: every frame of it was refused outside the "
                                                         "declared domain")  # none judged inside it
    assert "(0 of 6 inside" not in rows["Image size"]["evidence"] and "(6 of 6 inside" in rows["Image size"]["evidence"]
    wide = {**high, "height_m": [10.0, 120.0]}  # the same frames inside: judged, so the declared fog is covered
    judged = images(CampaignConfig(**base, odd=wide))
    rows = {r["name"]: r for r in odd_rows({**man, "config": {**man["config"], "odd": wide}}, judged,
                                           {"height": 0.2, "pitch": 0.2})}
    assert rows["Perturbation fog"]["evidence"] == "evaluated at severity 3: covered"
    # the pose-error margin: absorbed by beta only where beta covers it (EL-R14's required beta)
    man["config"]["core"]["safety"] = {"radius_m": 2.5, "beta": 1.7}
    short = {r["name"]: r for r in odd_rows(man, refused, {"height": 0.2, "pitch": 0.2}, need=1.853)}
    assert "NOT absorbed: beta = 1.7 where 1.853 is required" in short["Height"]["evidence"]
    assert "absorbs" not in short["Pitch"]["evidence"]
    enough = {r["name"]: r for r in odd_rows(man, refused, {"height": 0.2, "pitch": 0.2}, need=1.6)}
    assert "beta absorbs 20% around the nominal 50 m" in enough["Height"]["evidence"]


@pytest.mark.requirements("EL-R17")
def test_uav_el_land_outside_the_domain_is_a_decision_exit_0(tmp_path, capsys):
    from assurance.cli import main
    from assurance.dataio.uavid import write_image

    img, out = tmp_path / "frame.png", tmp_path / "d.json"
    write_image(img, scene_image(scene_ids()))
    assert main(["land", str(img), "--height", "120", "--monitor", "none", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["action"] == "default" and d["reason"] == "outside_odd: height 120 m not in [40, 60] m"
    assert "reason: outside_odd: height 120 m" in capsys.readouterr().out


@pytest.mark.requirements("EL-R17")
def test_uav_el_land_labels_checks_the_declared_domain_too(tmp_path, capsys, monkeypatch):
    from assurance.cli import main
    from assurance.dataio.uavid import write_image
    from el.classes.labels import ids_to_colors

    labels, out = tmp_path / "labels.png", tmp_path / "d.json"
    write_image(labels, ids_to_colors(scene_ids()))
    assert main(["land", "--labels", str(labels), "--json", str(out)]) == 0  # the embedded default: 4K frames only
    assert json.loads(out.read_text())["reason"] == "outside_odd: image_width 256 px not in [3840, 4096] px"
    monkeypatch.chdir(bench_system(tmp_path / "bench").parent)  # a system that admits the small test frame
    assert main(["land", "--labels", str(labels), "--pitch", "70", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["action"] == "default" and d["reason"] == "outside_odd: pitch 70 deg not in [36, 54] deg"
    assert d["candidates"] == [] and d["config"]["odd"]["pitch_deg"] == [36.0, 54.0]
    assert "reason: outside_odd: pitch 70 deg" in capsys.readouterr().out
    assert main(["land", "--labels", str(labels), "--json", str(out)]) == 0  # inside: the CM decides
    assert not json.loads(out.read_text())["reason"].startswith("outside_odd")
