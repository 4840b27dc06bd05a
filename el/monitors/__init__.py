"""Runtime monitors (docs/architecture.md section 3.6): LHD, CH and MCD on HD patches around landing candidates.

What the decision loop calls::

    monitor = build_monitor("lhd+ch:tau=0.25", labels=segmenter.labels,    # None for "none"
                            network_classes=None, model=segmenter)         # refused here if it cannot run
    verdict = monitor.check(hd_image, candidate, segmenter, seed=seed)       # MonitorVerdict

What a campaign calls to segment a patch once and judge it with many configurations::

    patch = extract_patch(hd_image, candidate, margin=0.25)
    softmax = segmenter.predict_patch(patch.rgb)                    # LHD, LHD+CH
    samples = segmenter.mc_dropout(patch.rgb, 30, rho, seed)        # every MCD config with this rho
    verdict = monitor.check_scores(softmax or samples, patch.disc_mask)

Every monitor gives each candidate a score (higher = more likely unsafe) and rejects it iff the score
is above its threshold (``verdict.score``, ``verdict.threshold``). Monitors beyond the paper's are in
the registry (``el.monitors.registry``: built-ins and the ``uav_el.monitors`` entry points).
"""

from el.landing.forbidden import forbidden_pixels
from el.monitors.base import CandidateContext, Judgement, Monitor, PatchMonitor, PatchSegmenter
from el.monitors.build import build_monitor
from el.monitors.ch import CHMonitor, ch_rule, rejected_label_counts
from el.monitors.hierarchy import ClassHierarchy, default_hierarchy
from el.monitors.lhd import LHDMonitor, forbidden_counts, lhd_rule
from el.monitors.mcd import MCDMonitor, mcd_score
from el.monitors.patches import Patch, extract_patch
from el.monitors.registry import ENTRY_POINT_GROUP, MonitorEntry, monitor_names, register_monitor
from el.monitors.spec import (
    DEMO_GRID,
    PAPER_GRID,
    GenericSpec,
    MonitorSpec,
    monitor_name,
    parse_monitor_spec,
)

__all__ = [
    "DEMO_GRID",
    "ENTRY_POINT_GROUP",
    "PAPER_GRID",
    "CHMonitor",
    "CandidateContext",
    "GenericSpec",
    "Judgement",
    "MonitorEntry",
    "ClassHierarchy",
    "LHDMonitor",
    "MCDMonitor",
    "Monitor",
    "PatchMonitor",
    "MonitorSpec",
    "Patch",
    "PatchSegmenter",
    "build_monitor",
    "ch_rule",
    "default_hierarchy",
    "extract_patch",
    "forbidden_counts",
    "forbidden_pixels",
    "lhd_rule",
    "mcd_score",
    "monitor_name",
    "monitor_names",
    "parse_monitor_spec",
    "register_monitor",
    "rejected_label_counts",
]
