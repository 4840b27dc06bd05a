"""A campaign worker decodes a scene once for its scenarios (``assurance.campaign.frame_cache``): the kept frame is
read-only, and a file replaced or changed is decoded again."""

from __future__ import annotations

import numpy as np
import pytest

from assurance.campaign import frame_cache
from assurance.dataio.uavid import write_image
from el.base.imageio import read_image


def test_a_kept_frame_is_read_only_and_a_replaced_file_is_read_again(tmp_path):
    path = tmp_path / "f.png"
    write_image(path, np.zeros((8, 12, 3), np.uint8))
    frame_cache.clear()
    calls = []

    def load():
        calls.append(1)
        return read_image(path)

    first = frame_cache.cached("image", frame_cache.file_key(path), load)
    again = frame_cache.cached("image", frame_cache.file_key(path), load)
    assert again is first and len(calls) == 1
    with pytest.raises(ValueError):
        first[0, 0, 0] = 1  # a stage writing into the kept frame raises instead of changing the next task's pixels
    write_image(path, np.full((8, 12, 3), 7, np.uint8))  # replaced (temporary file + rename)
    fresh = frame_cache.cached("image", frame_cache.file_key(path), load)
    assert len(calls) == 2 and int(fresh[0, 0, 0]) == 7
    assert frame_cache.cached("labels", frame_cache.file_key(path, "other"), lambda: (fresh, {})) == (fresh, {})


def test_tasks_are_planned_scene_by_scene(tmp_path):
    from helpers import write_textured_scenes

    from assurance.campaign.run import CampaignConfig, plan

    data = write_textured_scenes(tmp_path / "data", range(3))
    config = CampaignConfig(perturbations=("none", "fog", "brightness"), monitors=("lhd",))
    tasks = plan(data, config)
    assert [t.sample.key for t in tasks[:3]] == [tasks[0].sample.key] * 3  # a scene's scenarios together
    assert [(t.perturbation, t.severity) for t in tasks[:3]] == config.scenarios()
    assert len({t.sample.key for t in tasks}) == 3 and len(tasks) == 9
