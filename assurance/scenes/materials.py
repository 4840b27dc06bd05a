"""Shader materials: how much noise of each ground scale a surface shows, and its cell pattern.

Noise octaves are fixed world scales (``OCTAVE_SCALES_M``); a material sets their amplitudes
(relative brightness), a colour-drift amplitude, a per-pixel grain, and an optional cell grid
(pavers, slabs, windows, roof tiles, metal ribs, mowing stripes). Several classes share
materials on purpose: asphalt roads and asphalt parking lots, concrete roofs and plazas.
"""

from __future__ import annotations

from dataclasses import dataclass

OCTAVE_SCALES_M: tuple[float, float, float, float] = (9.0, 2.2, 0.55, 0.14)


@dataclass(frozen=True)
class Material:
    """Noise amplitudes per octave, colour drift, grain, default cell grid and cell contrast."""

    name: str
    noise: tuple[float, float, float, float]
    chroma: float = 0.03
    grain: float = 0.03
    cell: tuple[float, float, float, float] | None = None  # size_u, size_v (m), half_u, half_v (fraction)
    cell_gain: float = 1.0  # cell colour = rgb * gain unless the look gives cell_rgb
    cell_var: float = 0.0  # per-cell random brightness variation


MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("asphalt", (0.05, 0.05, 0.06, 0.06), chroma=0.012, grain=0.035),
        Material("asphalt_worn", (0.09, 0.08, 0.07, 0.06), chroma=0.02, grain=0.035),
        Material("concrete_slab", (0.04, 0.04, 0.04, 0.04), grain=0.03, cell=(4.5, 4.0, 0.49, 0.49),
                 cell_gain=1.06, cell_var=0.08),
        Material("paint", (0.06, 0.08, 0.10, 0.08), chroma=0.01, grain=0.03),
        Material("pavers", (0.04, 0.04, 0.04, 0.04), grain=0.035, cell=(0.6, 0.3, 0.44, 0.40),
                 cell_gain=1.12, cell_var=0.10),
        Material("slabs", (0.04, 0.04, 0.04, 0.04), grain=0.03, cell=(1.0, 1.0, 0.46, 0.46),
                 cell_gain=1.08, cell_var=0.06),
        Material("curb", (0.05, 0.05, 0.05, 0.04), grain=0.02),
        Material("grass", (0.06, 0.07, 0.09, 0.10), chroma=0.035, grain=0.05),
        Material("grass_mown", (0.05, 0.06, 0.08, 0.09), chroma=0.03, grain=0.05, cell=(100.0, 3.0, 0.5, 0.25),
                 cell_gain=1.07),
        Material("soil", (0.08, 0.08, 0.09, 0.09), chroma=0.025, grain=0.05),
        Material("gravel", (0.05, 0.05, 0.09, 0.16), chroma=0.015, grain=0.09),
        Material("sand", (0.08, 0.06, 0.06, 0.05), chroma=0.02, grain=0.04),
        Material("water", (0.06, 0.05, 0.03, 0.02), chroma=0.02, grain=0.015),
        Material("court", (0.05, 0.04, 0.03, 0.03), chroma=0.01, grain=0.03),
        Material("roof_membrane", (0.05, 0.05, 0.04, 0.04), grain=0.03, cell=(5.0, 1.0, 0.49, 0.5),
                 cell_gain=1.03, cell_var=0.05),
        Material("roof_gravel", (0.07, 0.06, 0.09, 0.14), grain=0.08),
        Material("roof_concrete", (0.05, 0.05, 0.05, 0.04), grain=0.04, cell=(3.0, 3.0, 0.48, 0.48),
                 cell_gain=1.04, cell_var=0.06),
        Material("roof_green", (0.07, 0.09, 0.10, 0.10), chroma=0.04, grain=0.05),
        Material("roof_tiles", (0.06, 0.06, 0.05, 0.05), chroma=0.02, grain=0.04, cell=(0.32, 0.36, 0.5, 0.38),
                 cell_gain=1.08, cell_var=0.10),
        Material("roof_metal", (0.05, 0.05, 0.04, 0.03), grain=0.02, cell=(0.8, 100.0, 0.3, 0.5),
                 cell_gain=1.10, cell_var=0.02),
        Material("solar", (0.03, 0.03, 0.02, 0.02), grain=0.02, cell=(1.0, 1.7, 0.46, 0.47),
                 cell_gain=1.35, cell_var=0.08),
        Material("facade", (0.05, 0.04, 0.03, 0.02), grain=0.025, cell=(3.2, 3.2, 0.25, 0.22),
                 cell_var=0.35),
        Material("curtain_wall", (0.05, 0.04, 0.03, 0.02), grain=0.02, cell=(1.6, 3.4, 0.46, 0.42),
                 cell_var=0.25),
        Material("metal_wall", (0.05, 0.04, 0.03, 0.02), grain=0.02, cell=(0.7, 100.0, 0.32, 0.5),
                 cell_gain=1.07),
        Material("car_paint", (0.02, 0.02, 0.02, 0.02), chroma=0.0, grain=0.02),
        Material("car_glass", (0.04, 0.04, 0.04, 0.03), chroma=0.0, grain=0.02),
        Material("cloth", (0.05, 0.05, 0.05, 0.05), chroma=0.02, grain=0.04),
        Material("foliage", (0.07, 0.10, 0.16, 0.30), chroma=0.04, grain=0.09),
        Material("shrub", (0.07, 0.10, 0.2, 0.18), chroma=0.035, grain=0.06),
        Material("bark", (0.05, 0.05, 0.05, 0.05), grain=0.04),
        Material("wood", (0.05, 0.05, 0.06, 0.05), grain=0.04, cell=(0.15, 100.0, 0.4, 0.5), cell_gain=1.1),
        Material("metal", (0.04, 0.04, 0.03, 0.03), grain=0.025),
        Material("fabric", (0.03, 0.03, 0.03, 0.03), chroma=0.01, grain=0.03),
    )
}

MATERIAL_IDS: dict[str, int] = {name: i for i, name in enumerate(MATERIALS)}
