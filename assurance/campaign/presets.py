"""Campaign presets (``assurance/presets.yaml``), the monitor keywords they may use, and which configurations a
system's model can run.

A preset's monitors are the system's deployed configuration (``deployed``) and the paper's configurations (a grid
keyword, or named): :func:`campaign_monitors` checks each once against the system's network and label set before
any task runs (:func:`monitor_support`: the monitor built in the network's label set, its required capabilities,
the network its fitted model was made on). A configuration the network cannot run is left out, with its reason,
when the preset brought it in; the campaign is refused (:class:`MonitorSupportError`, naming the configuration)
when it is the deployed one or the user asked for it (``--monitors``, a calibration card). A preset evaluates
every frame of the data unless it states a number (``images``: the release evidence's size) or ``--images`` cuts
it; the command says so when either does. A preset's perturbations are the system's (the keyword ``declared``:
``assurance.campaign.perturbation_plan``) unless it names them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

from assurance.campaign.perturbation_plan import Planned, default_plan, expand, severity_caps
from assurance.campaign.run import CampaignConfig
from el.base import safeyaml
from el.flight.pipeline import PipelineConfig
from el.monitors import DEMO_GRID, PAPER_GRID, build_monitor, monitor_name
from el.monitors.capabilities import MonitorSupportError, check_monitor_capabilities  # MonitorSupportError: re-exported
from el.segmentation.contract import labels_of

GRIDS = {"paper-grid": PAPER_GRID, "demo-grid": DEMO_GRID}
DEPLOYED = "deployed"


def load_presets() -> dict[str, dict[str, Any]]:
    """The campaign presets (``assurance/presets.yaml``; the packaged file read once, each caller its own copy)."""
    return safeyaml.safe_load(_presets_text())


@cache
def _presets_text() -> str:
    return resources.files("assurance").joinpath("presets.yaml").read_text(encoding="utf-8")


def _deployed_name(deployed: str | None) -> str:
    """The deployed configuration's canonical name: the system's (``deployed``), else the flight code's default."""
    return monitor_name(deployed) if deployed else PipelineConfig().monitor_name


def preset_items(value: str | Sequence[str], deployed: str | None = None) -> list[tuple[str, bool]]:
    """A preset's monitor list as (configuration, required) with its keywords expanded: a grid name (``paper-grid``,
    ``demo-grid``: not required) and ``deployed`` (required): the system file's monitor (``deployed``), else the
    configuration the flight code ships with (``el.flight.pipeline.PipelineConfig``); a named configuration is not
    required (a preset's choice, not the user's). A system deploying no monitor (``none``) adds nothing."""
    out: list[tuple[str, bool]] = []
    for item in [value] if isinstance(value, str) else value:
        if item in GRIDS:
            out.extend((m, False) for m in GRIDS[item])
        elif item == DEPLOYED:
            name = _deployed_name(deployed)
            if name != "none":  # a system deploying no monitor: the CM alone, in every row
                out.append((name, True))
        else:
            out.append((item, False))
    return out


def resolve_monitors(value: str | Sequence[str], deployed: str | None = None) -> tuple[str, ...]:
    """A preset's monitor list with its keywords expanded (:func:`preset_items`), duplicates dropped."""
    return tuple(dict.fromkeys(m for m, _ in preset_items(value, deployed)))


def monitor_support(spec: str, model: Any) -> str | None:
    """Why ``model`` cannot run the configuration ``spec`` (None: it can): the monitor is built once in the
    model's label set (a label set it cannot read, a missing or unreadable model file), then its required
    capabilities (MC dropout on a network without dropout) and the network its fitted model was made on are
    checked. Nothing is judged."""
    try:
        monitor = build_monitor(spec, labels=labels_of(model), network_classes=getattr(model, "network_classes", None))
        if monitor is not None:
            check_monitor_capabilities(monitor, model)
            monitor.check_network(model)
    except Exception as exc:  # any refusal is the reason; nothing has run
        text = str(exc).strip().splitlines()
        return text[0] if text else type(exc).__name__
    return None


@dataclass(frozen=True)
class MonitorChoice:
    """The configurations a campaign evaluates (canonical names, in order) and those left out, with why."""

    monitors: tuple[str, ...]
    left_out: tuple[tuple[str, str], ...] = field(default_factory=tuple)


def campaign_monitors(preset: str, *, deployed: str | None = None, given: Sequence[str] | None = None,
                      extra: Sequence[str] = (), model: Any = None, where: str = "the system file") -> MonitorChoice:
    """The configurations of a campaign: ``given`` (``--monitors``, each required) or the preset's
    (:func:`preset_items`), then ``extra`` (calibration cards' specs, required), duplicates dropped by canonical
    name. With ``model``, each is checked once (:func:`monitor_support`): one not required that the model cannot
    run is left out (``left_out``: its name and why); one required raises :class:`MonitorSupportError` naming it,
    why and ``where`` (the system file)."""
    presets = load_presets()
    if preset not in presets:
        raise ValueError(f"unknown preset {preset!r}; valid: {', '.join(presets)}")
    items = [(m, True) for m in given] if given else preset_items(presets[preset]["monitors"], deployed)
    items += [(m, True) for m in extra]
    required: dict[str, bool] = {}
    for spec, must in items:
        name = monitor_name(spec)
        required[name] = required.get(name, False) or must
    kept, left = [], []
    for name, must in required.items():
        why = None if model is None else monitor_support(name, model)
        if why is None:
            kept.append(name)
        elif must:
            raise MonitorSupportError(f"monitor {name!r} cannot run on the network of {where}: {why}")
        else:
            left.append((name, why))
    return MonitorChoice(tuple(kept), tuple(left))


def preset_config(name: str, *, deployed: str | None = None, plan: Sequence[Planned] | None = None,
                  **overrides: Any) -> CampaignConfig:
    """The CampaignConfig of a named preset, with non-None overrides applied; ``deployed``: the monitor the
    preset's ``deployed`` keyword stands for (the system file's); ``plan``: the system's perturbations the preset's
    ``declared`` keyword stands for (``assurance.campaign.perturbation_plan.system_plan``; None: the embedded
    default's, the paper's six). A declared maximum below the severities caps that perturbation's
    (``severity_caps``) unless the severities are given or the preset goes ``beyond_declared``. ``images``: the
    preset's stated number of scenes (None: every frame of the data)."""
    presets = load_presets()
    if name not in presets:
        raise ValueError(f"unknown preset {name!r}; valid: {', '.join(presets)}")
    p = presets[name]
    plan = default_plan() if plan is None else tuple(plan)
    monitors = resolve_monitors(p["monitors"], deployed)
    perturbations = tuple(overrides.get("perturbations") or expand(p["perturbations"], plan))
    severities = tuple(overrides.get("severities") or p["severities"])
    capped = not overrides.get("severities") and not p.get("beyond_declared")
    kwargs: dict[str, Any] = {
        "perturbations": perturbations,
        "severities": severities,
        "monitors": tuple(monitors),
        "images": p.get("images"),
        "severity_caps": severity_caps(plan, perturbations, severities) if capped else None,
    }
    kwargs.update({k: v for k, v in overrides.items() if v is not None})
    return CampaignConfig(**kwargs)
