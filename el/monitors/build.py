"""``build_monitor``: a monitor object from its name (or ``MonitorSpec``)."""

from __future__ import annotations

import time

from el.monitors.base import Clock, Monitor
from el.monitors.ch import CHMonitor
from el.monitors.hierarchy import ClassHierarchy
from el.monitors.lhd import LHDMonitor
from el.monitors.mcd import MCDMonitor
from el.monitors.spec import MonitorSpec, parse_monitor_spec


def build_monitor(
    spec: str | MonitorSpec | None,
    *,
    margin: float = 0.25,
    max_side: int | None = None,
    clock: Clock = time.perf_counter,
    hierarchy: ClassHierarchy | None = None,
) -> Monitor | None:
    """Build the monitor a spec names; ``"none"`` (or None) gives None: no runtime monitor.

    Parameters
    ----------
    spec : str, MonitorSpec or None
        E.g. ``"lhd+ch+mcd:tau=0.25,n=10,rho=0.9"`` (see ``parse_monitor_spec``).
    margin, max_side, clock
        Patch geometry and timing, shared by every monitor kind (see ``Monitor``).
    hierarchy : ClassHierarchy, optional
        For CH; defaults to the shipped ``hierarchy.yaml``.

    Raises
    ------
    ValueError
        A bad spec (the message lists the valid forms) or bad patch parameters.

    Examples
    --------
    >>> build_monitor("lhd+mcd:n=10,rho=0.9").name
    'lhd+mcd:n=10,rho=0.9'
    >>> build_monitor("none") is None
    True
    """
    parsed = parse_monitor_spec(spec)
    if parsed is None:
        return None
    common = {"margin": margin, "max_side": max_side, "clock": clock}
    rule: LHDMonitor
    if parsed.tau is not None:
        rule = CHMonitor(tau=parsed.tau, hierarchy=hierarchy, **common)
    else:
        rule = LHDMonitor(**common)
    if parsed.n is None or parsed.rho is None:
        return rule
    return MCDMonitor(rule, n=parsed.n, rho=parsed.rho)
