"""A frame brings its own pose: ``decide(frame, pose=...)`` plans with it and records it; None is the nominal."""

from __future__ import annotations

import jsonschema
from helpers import OracleSegmenter, scene_ids, scene_image

from el.base.decision import decision_schema
from el.flight.pipeline import EmergencyLanding, PipelineConfig
from el.geometry.camera import Pose
from el.geometry.config import CoreConfig

WW = 128


def _landing() -> EmergencyLanding:
    return EmergencyLanding(PipelineConfig(core=CoreConfig(working_width=WW), monitor="lhd"),
                            segmenter=OracleSegmenter(WW))


def test_the_frame_pose_sets_the_safety_radius_and_is_recorded():
    el, image = _landing(), scene_image(scene_ids())
    nominal = el.decide(image)
    assert nominal.input["pose"] == {"height_m": 50.0, "pitch_deg": 45.0, "source": "nominal"}
    same = el.decide(image, pose=Pose())
    assert [(c.x, c.y, c.radius_px, c.hazard) for c in same.candidates] == \
        [(c.x, c.y, c.radius_px, c.hazard) for c in nominal.candidates] and same.input["pose"]["source"] == "frame"
    low = el.decide(image, pose=Pose(height_m=25.0, pitch_deg=45.0))  # closer to the ground: larger discs
    assert low.input["pose"] == {"height_m": 25.0, "pitch_deg": 45.0, "source": "frame"}
    assert low.default_area.radius_px > nominal.default_area.radius_px
    assert low.config == nominal.config  # the configuration is the nominal one; the pose is the frame's
    for d in (nominal, low):
        jsonschema.validate(d.to_dict(), decision_schema())


def test_a_malformed_pose_ends_in_the_default_action():
    d = _landing().decide(scene_image(scene_ids()), pose={"height_m": 30})
    assert d.action == "default"
    assert d.reason.startswith("fault: pose: ValueError: pose must be an el.geometry.camera.Pose")


def test_a_pose_is_checked_and_recorded_as_plain_numbers():
    import json

    import numpy as np

    el, image = _landing(), scene_image(scene_ids())
    d = el.decide(image, pose=Pose(height_m=np.float32(40.0), pitch_deg=np.int64(50)))
    assert d.input["pose"] == {"height_m": 40.0, "pitch_deg": 50.0, "source": "frame"}
    json.loads(d.to_json())  # numpy scalars would not serialise
    bad = el.decide(image, pose=Pose(height_m=True))
    assert bad.reason.startswith("fault: pose: ValueError: pose height_m must be a number")
    assert bad.input["width"] == image.shape[1]  # the frame was read: its own size and default area
    assert bad.default_area.y < image.shape[0]
    jsonschema.validate(bad.to_dict(), decision_schema())
