"""Campaign presets (``assurance/presets.yaml``) and the monitor keywords they may use."""

from __future__ import annotations

from collections.abc import Sequence
from importlib import resources
from typing import Any

from assurance.campaign.run import CampaignConfig
from el import safeyaml
from el.monitors import DEMO_GRID, PAPER_GRID

GRIDS = {"paper-grid": PAPER_GRID, "demo-grid": DEMO_GRID}


def load_presets() -> dict[str, dict[str, Any]]:
    """The campaign presets (``assurance/presets.yaml``)."""
    text = resources.files("assurance").joinpath("presets.yaml").read_text(encoding="utf-8")
    return safeyaml.safe_load(text)


def resolve_monitors(value: str | Sequence[str], deployed: str | None = None) -> tuple[str, ...]:
    """A preset's monitor list with its keywords expanded: a grid name (``paper-grid``, ``demo-grid``) and
    ``deployed``: the system file's monitor (``deployed``), else the configuration the flight code ships with
    (``el.pipeline.PipelineConfig``)."""
    from el.monitors import monitor_name
    from el.pipeline import PipelineConfig

    out: list[str] = []
    for item in [value] if isinstance(value, str) else value:
        if item in GRIDS:
            out.extend(GRIDS[item])
        elif item == "deployed":
            out.append(monitor_name(deployed) if deployed else PipelineConfig().monitor_name)
        else:
            out.append(item)
    return tuple(dict.fromkeys(out))


def preset_config(name: str, *, deployed: str | None = None, **overrides: Any) -> CampaignConfig:
    """The CampaignConfig of a named preset, with non-None overrides applied; ``deployed``: the monitor the
    preset's ``deployed`` keyword stands for (the system file's)."""
    presets = load_presets()
    if name not in presets:
        raise ValueError(f"unknown preset {name!r}; valid: {', '.join(presets)}")
    p = presets[name]
    monitors = resolve_monitors(p["monitors"], deployed)
    kwargs: dict[str, Any] = {
        "perturbations": tuple(p["perturbations"]),
        "severities": tuple(p["severities"]),
        "monitors": tuple(monitors),
        "images": p.get("images"),
    }
    kwargs.update({k: v for k, v in overrides.items() if v is not None})
    return CampaignConfig(**kwargs)
