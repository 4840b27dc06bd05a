"""Scene styles: layout mix, palettes and lighting. Some styles are held out of training.

A style fixes what a city looks like (which block types, road widths, building heights, how many
trees, cars and people, which colours); a lighting fixes the sun and the sky. Palettes overlap on
purpose across classes (grey roofs and asphalt, green roofs and lawns, red courts and tile roofs)
so that colour alone cannot tell the classes apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

RGB = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class Lighting:
    """Sun elevation range (deg), sun and sky light colours, haze and exposure range."""

    name: str
    elevation_deg: tuple[float, float]
    sun: RGB
    ambient: RGB
    haze: float = 0.04
    exposure: tuple[float, float] = (0.95, 1.1)


LIGHTINGS: dict[str, Lighting] = {
    lt.name: lt
    for lt in (
        Lighting(name="noon", elevation_deg=(52, 72), sun=(0.78, 0.76, 0.70), ambient=(0.42, 0.44, 0.48)),
        Lighting(name="morning", elevation_deg=(24, 40), sun=(0.80, 0.72, 0.58), ambient=(0.38, 0.41, 0.47),
                 haze=0.07),
        Lighting(name="afternoon", elevation_deg=(32, 50), sun=(0.80, 0.75, 0.64), ambient=(0.40, 0.42, 0.46)),
        Lighting(name="overcast", elevation_deg=(40, 65), sun=(0.22, 0.22, 0.23), ambient=(0.78, 0.80, 0.82),
                 haze=0.08, exposure=(0.9, 1.05)),
        Lighting(name="hazy", elevation_deg=(35, 60), sun=(0.55, 0.54, 0.50), ambient=(0.58, 0.60, 0.64),
                 haze=0.14),
        # held out: low golden sun with long shadows
        Lighting(name="golden", elevation_deg=(14, 24), sun=(0.86, 0.64, 0.40), ambient=(0.36, 0.38, 0.46),
                 haze=0.08, exposure=(1.0, 1.15)),
    )
}


@dataclass(frozen=True, kw_only=True)
class Palette:
    """Colour choices (sRGB in [0, 1]) per material family; each object draws one and jitters it."""

    asphalt: tuple[RGB, ...] = ((0.30, 0.30, 0.31), (0.36, 0.36, 0.37), (0.25, 0.25, 0.27), (0.42, 0.41, 0.40))
    lot_asphalt: tuple[RGB, ...] = ((0.31, 0.31, 0.32), (0.38, 0.38, 0.38), (0.27, 0.27, 0.28))
    paving: tuple[RGB, ...] = ((0.55, 0.54, 0.52), (0.62, 0.60, 0.56), (0.46, 0.46, 0.47), (0.58, 0.48, 0.42),
                               (0.40, 0.40, 0.42))
    sidewalk: tuple[RGB, ...] = ((0.58, 0.57, 0.55), (0.50, 0.50, 0.50), (0.64, 0.62, 0.58), (0.44, 0.44, 0.45))
    roof: tuple[RGB, ...] = ((0.45, 0.45, 0.46), (0.34, 0.34, 0.35), (0.60, 0.59, 0.57), (0.28, 0.28, 0.30),
                             (0.72, 0.72, 0.70), (0.52, 0.47, 0.42), (0.38, 0.40, 0.34))
    roof_pitched: tuple[RGB, ...] = ((0.55, 0.30, 0.22), (0.40, 0.26, 0.22), (0.32, 0.32, 0.34),
                                     (0.47, 0.36, 0.30), (0.25, 0.26, 0.29))
    green_roof: tuple[RGB, ...] = ((0.33, 0.40, 0.22), (0.38, 0.42, 0.28))
    facade: tuple[RGB, ...] = ((0.75, 0.72, 0.66), (0.66, 0.62, 0.56), (0.58, 0.58, 0.58), (0.70, 0.60, 0.50),
                               (0.52, 0.40, 0.34), (0.80, 0.78, 0.74), (0.45, 0.47, 0.50))
    glass: tuple[RGB, ...] = ((0.24, 0.30, 0.36), (0.20, 0.24, 0.28), (0.32, 0.38, 0.42), (0.16, 0.18, 0.20))
    grass: tuple[RGB, ...] = ((0.36, 0.48, 0.22), (0.42, 0.50, 0.26), (0.32, 0.42, 0.20), (0.48, 0.50, 0.30))
    dry_grass: tuple[RGB, ...] = ((0.52, 0.50, 0.34), (0.46, 0.46, 0.30))
    tree: tuple[RGB, ...] = ((0.22, 0.36, 0.14), (0.27, 0.40, 0.17), (0.20, 0.31, 0.15), (0.30, 0.40, 0.20),
                             (0.24, 0.34, 0.20))
    shrub: tuple[RGB, ...] = ((0.26, 0.40, 0.16), (0.30, 0.42, 0.20), (0.24, 0.36, 0.18))
    soil: tuple[RGB, ...] = ((0.47, 0.40, 0.32), (0.40, 0.34, 0.27), (0.55, 0.48, 0.38))
    gravel: tuple[RGB, ...] = ((0.56, 0.54, 0.50), (0.50, 0.49, 0.47), (0.62, 0.58, 0.52))
    sand: tuple[RGB, ...] = ((0.72, 0.66, 0.52), (0.66, 0.60, 0.48))
    court: tuple[RGB, ...] = ((0.55, 0.30, 0.25), (0.30, 0.45, 0.30), (0.28, 0.38, 0.52), (0.40, 0.50, 0.35))
    water: tuple[RGB, ...] = ((0.25, 0.33, 0.36), (0.30, 0.38, 0.40))
    paint: tuple[RGB, ...] = ((0.86, 0.86, 0.84), (0.82, 0.80, 0.76))
    paint_centre: tuple[RGB, ...] = ((0.86, 0.86, 0.84), (0.85, 0.72, 0.30))
    car: tuple[RGB, ...] = ((0.85, 0.85, 0.85), (0.62, 0.63, 0.65), (0.40, 0.41, 0.43), (0.12, 0.12, 0.13),
                            (0.20, 0.24, 0.36), (0.55, 0.15, 0.14), (0.30, 0.32, 0.30), (0.72, 0.70, 0.64),
                            (0.90, 0.90, 0.90), (0.45, 0.38, 0.30))
    clothing: tuple[RGB, ...] = ((0.15, 0.15, 0.17), (0.85, 0.85, 0.85), (0.25, 0.30, 0.45), (0.55, 0.20, 0.18),
                                 (0.50, 0.48, 0.42), (0.30, 0.40, 0.30), (0.70, 0.60, 0.30), (0.35, 0.35, 0.38))
    clutter: tuple[RGB, ...] = ((0.40, 0.36, 0.30), (0.30, 0.32, 0.34), (0.55, 0.55, 0.55), (0.45, 0.30, 0.20),
                                (0.20, 0.35, 0.50), (0.60, 0.25, 0.20), (0.70, 0.70, 0.68))


TEMPERATE = Palette()

AUTUMN = Palette(
    tree=((0.55, 0.40, 0.16), (0.60, 0.30, 0.14), (0.42, 0.38, 0.16), (0.30, 0.36, 0.16), (0.62, 0.50, 0.20)),
    grass=((0.46, 0.48, 0.26), (0.50, 0.48, 0.30), (0.40, 0.44, 0.24)),
    shrub=((0.45, 0.36, 0.18), (0.38, 0.40, 0.20)),
)

MEDITERRANEAN = Palette(
    roof_pitched=((0.66, 0.38, 0.26), (0.60, 0.34, 0.24), (0.70, 0.45, 0.32), (0.52, 0.32, 0.24)),
    facade=((0.84, 0.78, 0.64), (0.80, 0.70, 0.56), (0.88, 0.84, 0.76), (0.76, 0.62, 0.48)),
    paving=((0.66, 0.60, 0.50), (0.58, 0.50, 0.42), (0.70, 0.66, 0.58), (0.52, 0.46, 0.40)),
    grass=((0.50, 0.50, 0.30), (0.44, 0.48, 0.26), (0.56, 0.52, 0.36)),
    soil=((0.60, 0.50, 0.38), (0.55, 0.44, 0.34)),
)


@dataclass(frozen=True, kw_only=True)
class Style:
    """What a city looks like: block types and their weights, street sizes, densities, palette, lights."""

    name: str
    blocks: dict[str, float]
    block_size: tuple[float, float] = (40.0, 80.0)
    lanes: dict[int, float] = field(default_factory=lambda: {2: 0.6, 4: 0.4})
    lane_width: tuple[float, float] = (3.0, 3.6)
    parking_lane_prob: float = 0.6
    sidewalk_width: tuple[float, float] = (2.5, 5.0)
    verge_prob: float = 0.3
    verge_parking_prob: float = 0.35  # a verge at least 2 m wide gets cars parked on it
    drop_road_prob: float = 0.1
    building_height: tuple[float, float] = (8.0, 25.0)
    pitched_prob: float = 0.1
    street_tree_prob: float = 0.6
    street_tree_spacing: tuple[float, float] = (7.0, 13.0)
    tree_size: tuple[float, float] = (2.2, 5.0)
    parked_fill: float = 0.6
    moving_per_100m: float = 2.0
    people_per_100m2: float = 0.25
    palette: Palette = TEMPERATE
    lightings: tuple[str, ...] = ("noon", "morning", "afternoon", "overcast", "hazy")


STYLES: dict[str, Style] = {
    s.name: s
    for s in (
        Style(name="downtown",
              blocks={"perimeter": 4, "towers": 2, "plaza": 1.2, "parking": 0.8, "park": 0.5},
              lanes={2: 0.35, 4: 0.5, 6: 0.15}, building_height=(10.0, 25.0), block_size=(36.0, 70.0),
              people_per_100m2=0.5, moving_per_100m=3.0),
        Style(name="residential",
              blocks={"houses": 5, "park": 0.8, "perimeter": 0.8, "vacant": 0.3, "sports": 0.3, "parking": 0.4},
              lanes={2: 0.9, 4: 0.1}, building_height=(4.0, 10.0), pitched_prob=0.7, verge_prob=0.55,
              street_tree_prob=0.8, sidewalk_width=(1.8, 3.0), tree_size=(2.5, 5.5), people_per_100m2=0.12,
              moving_per_100m=1.0, block_size=(36.0, 70.0)),
        Style(name="industrial",
              blocks={"industrial": 5, "parking": 1.5, "vacant": 1.2, "perimeter": 0.5, "lawn": 0.4},
              lanes={2: 0.5, 4: 0.5}, building_height=(5.0, 14.0), street_tree_prob=0.25, verge_prob=0.4,
              parked_fill=0.35, people_per_100m2=0.05, block_size=(50.0, 95.0),
              lightings=("noon", "morning", "afternoon", "overcast", "hazy")),
        Style(name="park",
              blocks={"park": 4, "lawn": 1.5, "sports": 1.0, "houses": 1.0, "plaza": 0.6, "parking": 0.5},
              lanes={2: 0.85, 4: 0.15}, building_height=(4.0, 14.0), street_tree_prob=0.8, verge_prob=0.5,
              pitched_prob=0.4, people_per_100m2=0.3, moving_per_100m=1.0, block_size=(42.0, 80.0)),
        Style(name="campus",
              blocks={"towers": 1.5, "lawn": 2.0, "plaza": 1.2, "parking": 1.2, "perimeter": 1.0, "sports": 0.6,
                      "park": 0.6},
              building_height=(8.0, 20.0), people_per_100m2=0.35, block_size=(42.0, 85.0)),
    )
}

HELD_OUT_STYLES: dict[str, Style] = {
    s.name: s
    for s in (
        Style(name="old_town",
              blocks={"perimeter": 5, "plaza": 1.5, "houses": 1.0, "park": 0.4},
              lanes={2: 1.0}, lane_width=(2.7, 3.2), sidewalk_width=(1.5, 2.5), building_height=(7.0, 18.0),
              pitched_prob=0.75, street_tree_prob=0.35, block_size=(34.0, 60.0), drop_road_prob=0.1,
              people_per_100m2=0.6, moving_per_100m=1.5, palette=MEDITERRANEAN,
              lightings=("noon", "morning", "afternoon", "golden")),
        Style(name="autumn_suburb",
              blocks={"houses": 4, "park": 1.2, "lawn": 0.8, "parking": 0.5, "sports": 0.4},
              lanes={2: 0.9, 4: 0.1}, building_height=(4.0, 9.0), pitched_prob=0.8, verge_prob=0.6,
              street_tree_prob=0.9, tree_size=(2.5, 6.0), people_per_100m2=0.1, palette=AUTUMN,
              lightings=("golden", "overcast", "morning")),
    )
}

ALL_STYLES: dict[str, Style] = {**STYLES, **HELD_OUT_STYLES}
HELD_OUT_SHARE = 1 / 3  # share of val/test scenes drawn from the held-out styles


def get_style(name: str) -> Style:
    """Style by name; ValueError listing the known ones."""
    try:
        return ALL_STYLES[name]
    except KeyError:
        raise ValueError(f"unknown style {name!r}; known: {', '.join(ALL_STYLES)}") from None


def choose_style(rng: np.random.Generator, split: str | None) -> Style:
    """Draw a style: train uses STYLES only; val and test also draw held-out ones (1 in 3)."""
    train = list(STYLES.values())
    if split in ("val", "test") and rng.random() < HELD_OUT_SHARE:
        held = list(HELD_OUT_STYLES.values())
        return held[int(rng.integers(len(held)))]
    return train[int(rng.integers(len(train)))]


def jitter_rgb(rng: Any, rgb: RGB, brightness: float = 0.12, hue: float = 0.03) -> RGB:
    """A colour near ``rgb``: random brightness scale and a small per-channel shift."""
    scale = 1.0 + brightness * (2 * rng.random() - 1)
    return tuple(min(0.98, max(0.02, c * scale + hue * (2 * rng.random() - 1))) for c in rgb)  # type: ignore


def pick(rng: Any, choices: tuple[RGB, ...], brightness: float = 0.12, hue: float = 0.03) -> RGB:
    """One palette colour, jittered."""
    return jitter_rgb(rng, choices[int(rng.integers(len(choices)))], brightness, hue)
