"""``build_monitor``: a monitor object from its name (or ``MonitorSpec``), for a label set and a network."""

from __future__ import annotations

import time
from typing import Any

from el.classes.labels import UAVID, LabelSet
from el.monitors.base import Clock, Monitor
from el.monitors.capabilities import MonitorSupportError, check_monitor_capabilities, mapped_network_classes
from el.monitors.ch import CHMonitor
from el.monitors.hierarchy import ClassHierarchy, default_hierarchy
from el.monitors.lhd import LHDMonitor
from el.monitors.mcd import MCDMonitor
from el.monitors.patches import accepts_keyword
from el.monitors.registry import monitor_entry
from el.monitors.softmax_scores import check_network_classes
from el.monitors.spec import GenericSpec, MonitorSpec, parse_monitor_spec

NETWORK_CLASSES = "network_classes"


def _build_registered(spec: GenericSpec, labels: LabelSet, network_classes: int | None,
                      **common: object) -> Monitor:
    """A registered monitor from its spec; checks that it is a Monitor and names itself as asked.

    The label set is passed as ``labels=``; a factory that takes no ``labels`` keyword (a plugin written
    before label sets) is built only for the shipped UAVid set it was written for, and refused for another.
    ``network_classes`` goes to the factories that take it (the softmax-score monitors).
    """
    entry = monitor_entry(spec.kind)
    extra: dict[str, object] = {}
    if network_classes is not None and accepts_keyword(entry.factory, NETWORK_CLASSES):
        extra[NETWORK_CLASSES] = network_classes
    try:
        monitor = entry.factory(**spec.kwargs(), **common, **extra, labels=labels)
    except TypeError as exc:
        if "labels" not in str(exc):
            raise
        if labels != UAVID:  # the only set a plugin without a label set can mean
            raise MonitorSupportError(f"monitor {spec.kind!r} ({entry.source}) does not take a label set "
                                      f"(asked for {labels.name!r})") from None
        monitor = entry.factory(**spec.kwargs(), **common, **extra)
    if not isinstance(monitor, Monitor):
        raise ValueError(f"monitor {spec.kind!r} ({entry.source}) built a {type(monitor).__name__}, not a Monitor")
    if getattr(monitor.spec, "kind", None) != spec.kind:
        raise ValueError(f"monitor {spec.kind!r} ({entry.source}) names itself {monitor.name!r}")
    if getattr(monitor, "labels", UAVID) != labels:
        raise MonitorSupportError(f"monitor {spec.kind!r} ({entry.source}) ignored the label set {labels.name!r}")
    return monitor


def _rule_hierarchy(parsed: MonitorSpec, hierarchy: ClassHierarchy | None, labels: LabelSet) -> ClassHierarchy:
    """The CH tree: the one given, else the label set's; a set whose declared tree is broken is refused."""
    if hierarchy is not None:
        return hierarchy
    try:
        return default_hierarchy(labels)
    except ValueError as err:
        raise MonitorSupportError(f"monitor {parsed.name!r} cannot build its class hierarchy: {err}") from None


def build_monitor(
    spec: str | MonitorSpec | GenericSpec | None,
    *,
    margin: float = 0.25,
    max_side: int | None = None,
    clock: Clock = time.perf_counter,
    hierarchy: ClassHierarchy | None = None,
    labels: LabelSet,
    network_classes: int | None = None,
    model: Any = None,
) -> Monitor | None:
    """Build the monitor a spec names; ``"none"`` (or None) gives None: no runtime monitor.

    Parameters
    ----------
    spec : str, MonitorSpec, GenericSpec or None
        E.g. ``"lhd+ch+mcd:tau=0.25,n=10,rho=0.9"``, ``"lhd:threshold=0.01"``, ``"msp:threshold=0.6"``
        (see ``parse_monitor_spec``; registered monitors: ``el.monitors.registry``).
    margin, max_side, clock
        Patch geometry and timing, shared by every monitor kind (see ``Monitor``).
    hierarchy : ClassHierarchy, optional
        For CH; defaults to the label set's (``default_hierarchy``: the shipped ``hierarchy.yaml`` for UAVid).
    labels : LabelSet
        The label set of the segmenter's scores (``segmenter.labels``), given to the monitor.
    network_classes : int, optional
        The network's own class count, when a class map shows it in another label set (``len`` of the
        network's class names): the softmax-score monitors (``msp``, ``entropy``, ``energy``) normalise by
        it. None: the class count of the network ``model`` maps, when it is a class-mapped model, else the
        label set's (a network segmenting into ``labels``, as the shipped one).
    model : optional
        The segmentation model the monitor will judge with: when given, a monitor needing what it lacks
        (MC dropout on an ONNX network) is refused here (``check_monitor_capabilities``).

    Raises
    ------
    MonitorSupportError
        (a ValueError) A monitor that cannot run on this label set or model, naming the monitor's spec.
    ValueError
        A bad spec (the message lists the valid forms) or bad patch parameters.

    Examples
    --------
    >>> build_monitor("lhd+mcd:n=10,rho=0.9", labels=UAVID).name
    'lhd+mcd:n=10,rho=0.9'
    >>> build_monitor("none", labels=UAVID) is None
    True
    """
    network_classes = check_network_classes(network_classes if network_classes is not None
                                            else mapped_network_classes(model))
    parsed = parse_monitor_spec(spec)
    if parsed is None:
        return None
    monitor: Monitor
    if isinstance(parsed, GenericSpec):
        monitor = _build_registered(parsed, labels, network_classes, margin=margin, max_side=max_side, clock=clock)
    else:
        monitor = _build_paper(parsed, hierarchy, labels, margin=margin, max_side=max_side, clock=clock)
    if model is not None:
        check_monitor_capabilities(monitor, model)
    return monitor


def _build_paper(parsed: MonitorSpec, hierarchy: ClassHierarchy | None, labels: LabelSet, *, margin: float,
                 max_side: int | None, clock: Clock) -> Monitor:
    """LHD, LHD+CH, and MCD on either: the paper's monitors (their scores read no class count)."""
    mcd = parsed.n is not None and parsed.rho is not None  # MCD holds the threshold (its scores' range is wider)
    common = {"margin": margin, "max_side": max_side, "clock": clock, "labels": labels,
              "threshold": None if mcd else parsed.threshold}
    rule: LHDMonitor
    if parsed.tau is not None:
        rule = CHMonitor(tau=parsed.tau, hierarchy=_rule_hierarchy(parsed, hierarchy, labels), **common)
    else:
        rule = LHDMonitor(**common)
    if not mcd:
        return rule
    return MCDMonitor(rule, n=parsed.n, rho=parsed.rho, threshold=parsed.threshold)
