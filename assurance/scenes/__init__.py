"""Procedural oblique urban scenes in the UAVid layout, with a metric world model behind every pixel.

Public API: ``generate_scene``, ``generate_world``, ``ViewPlan``, ``render``, ``write_dataset``, ``World``,
``pixel_clearance_m``, the styles (``STYLES``, ``HELD_OUT_STYLES``) and the split seeds.
"""

from assurance.scenes.generate import (
    GENERATOR_VERSION,
    SPLIT_BASE,
    Scene,
    ViewPlan,
    default_geometry,
    frame_location,
    generate_scene,
    generate_world,
    scene_meta,
    scene_seed,
    write_dataset,
)
from assurance.scenes.renderer import Rendered, render
from assurance.scenes.styles import HELD_OUT_STYLES, STYLES
from assurance.scenes.world import World, pixel_clearance_m

__all__ = [
    "GENERATOR_VERSION",
    "HELD_OUT_STYLES",
    "SPLIT_BASE",
    "STYLES",
    "Rendered",
    "Scene",
    "ViewPlan",
    "World",
    "default_geometry",
    "frame_location",
    "generate_scene",
    "generate_world",
    "pixel_clearance_m",
    "render",
    "scene_meta",
    "scene_seed",
    "write_dataset",
]
