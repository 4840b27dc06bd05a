"""``build_monitor``: a monitor object from its name (or ``MonitorSpec``)."""

from __future__ import annotations

import time

from el.labels import UAVID, LabelSet
from el.monitors.base import Clock, Monitor
from el.monitors.ch import CHMonitor
from el.monitors.hierarchy import ClassHierarchy
from el.monitors.lhd import LHDMonitor
from el.monitors.mcd import MCDMonitor
from el.monitors.registry import monitor_entry
from el.monitors.spec import GenericSpec, MonitorSpec, parse_monitor_spec


def _build_registered(spec: GenericSpec, labels: LabelSet, **common: object) -> Monitor:
    """A registered monitor from its spec; checks that it is a Monitor and names itself as asked.

    A label set other than the default is passed as ``labels=`` (a monitor that does not take one
    is refused for it); with the default, the factory is called as before, without it.
    """
    entry = monitor_entry(spec.kind)
    if labels == UAVID:
        monitor = entry.factory(**spec.kwargs(), **common)
    else:
        try:
            monitor = entry.factory(**spec.kwargs(), **common, labels=labels)
        except TypeError as exc:
            if "labels" not in str(exc):
                raise
            raise ValueError(f"monitor {spec.kind!r} ({entry.source}) does not take a label set "
                             f"(asked for {labels.name!r})") from None
    if not isinstance(monitor, Monitor):
        raise ValueError(f"monitor {spec.kind!r} ({entry.source}) built a {type(monitor).__name__}, not a Monitor")
    if getattr(monitor.spec, "kind", None) != spec.kind:
        raise ValueError(f"monitor {spec.kind!r} ({entry.source}) names itself {monitor.name!r}")
    if getattr(monitor, "labels", UAVID) != labels:
        raise ValueError(f"monitor {spec.kind!r} ({entry.source}) ignored the label set {labels.name!r}")
    return monitor


def build_monitor(
    spec: str | MonitorSpec | GenericSpec | None,
    *,
    margin: float = 0.25,
    max_side: int | None = None,
    clock: Clock = time.perf_counter,
    hierarchy: ClassHierarchy | None = None,
    labels: LabelSet,
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
        For CH; defaults to the label set's (the shipped ``hierarchy.yaml`` for UAVid).
    labels : LabelSet, default ``el.labels.UAVID``
        The label set of the segmenter's scores (``segmenter.labels``), given to the monitor.

    Raises
    ------
    ValueError
        A bad spec (the message lists the valid forms) or bad patch parameters.

    Examples
    --------
    >>> build_monitor("lhd+mcd:n=10,rho=0.9", labels=UAVID).name
    'lhd+mcd:n=10,rho=0.9'
    >>> build_monitor("none", labels=UAVID) is None
    True
    """
    parsed = parse_monitor_spec(spec)
    if parsed is None:
        return None
    if isinstance(parsed, GenericSpec):
        return _build_registered(parsed, labels, margin=margin, max_side=max_side, clock=clock)
    mcd = parsed.n is not None and parsed.rho is not None  # MCD holds the threshold (its scores' range is wider)
    common = {"margin": margin, "max_side": max_side, "clock": clock, "labels": labels,
              "threshold": None if mcd else parsed.threshold}
    rule: LHDMonitor
    if parsed.tau is not None:
        rule = CHMonitor(tau=parsed.tau, hierarchy=hierarchy, **common)
    else:
        rule = LHDMonitor(**common)
    if not mcd:
        return rule
    return MCDMonitor(rule, n=parsed.n, rho=parsed.rho, threshold=parsed.threshold)
