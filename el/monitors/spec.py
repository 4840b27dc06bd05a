"""Monitor configurations by name: ``lhd``, ``lhd+ch:tau=0.25``, ``lhd+mcd:n=10,rho=0.9``, ...

A ``MonitorSpec`` is a frozen, validated value with a canonical ``name`` that round-trips through
``parse_monitor_spec``. ``"none"`` (no runtime monitor) parses to ``None``: the decision loop then
lands on the top-ranked candidate and records ``"monitor": null`` for it, rather than a verdict
that looks like a check that never happened.

The paper's 21 configurations are ``PAPER_GRID``; ``DEMO_GRID`` holds one of each kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import product
from typing import Any

from el.monitors.registry import monitor_entry
from el.monitors.walk import HAZARD, check_walk

NONE = "none"
PAPER_TAUS: tuple[float, ...] = (0.25, 0.125)
PAPER_NS: tuple[int, ...] = (10, 30)
PAPER_RHOS: tuple[float, ...] = (0.5, 0.75, 0.9)
MAX_MC_SAMPLES = 1000

VALID_FORMS = (
    "valid forms: none | lhd | lhd+ch:tau=T | lhd+mcd:n=N,rho=R | lhd+ch+mcd:tau=T,n=N,rho=R, "
    "with T the CH threshold in (0, 1) (paper: 0.25, 0.125), N the number of MC-dropout samples, "
    f"an integer in [2, {MAX_MC_SAMPLES}] (paper: 10, 30), and R the dropout keep probability in (0, 1] "
    "(paper: 0.5, 0.75, 0.9); e.g. 'lhd+ch+mcd:tau=0.25,n=10,rho=0.9'; any monitor also takes "
    "threshold=X (reject iff score > X; the paper's rules: 0), and registered monitors are named by "
    "their registry name (el.monitors.registry)"
)
THRESHOLD = "threshold"
WALK = "walk"  # el.monitors.walk: the order of the decision loop's walk (registered monitors only)


def validate_tau(tau: object) -> float:
    """CH threshold: a real number in (0, 1)."""
    if isinstance(tau, bool) or not isinstance(tau, int | float) or not (0.0 < float(tau) < 1.0):
        raise ValueError(f"tau must be a number in (0, 1), got {tau!r}")
    return float(tau)


def validate_n(n: object) -> int:
    """Number of MC-dropout samples: an integer in [2, MAX_MC_SAMPLES] (a deviation needs two)."""
    if isinstance(n, bool) or not isinstance(n, int) or not (2 <= n <= MAX_MC_SAMPLES):
        raise ValueError(f"n (MC-dropout samples) must be an integer in [2, {MAX_MC_SAMPLES}], got {n!r}")
    return int(n)


def validate_rho(rho: object) -> float:
    """Dropout keep probability rho: a real number in (0, 1] (drop probability ``1 - rho``)."""
    if isinstance(rho, bool) or not isinstance(rho, int | float) or not (0.0 < float(rho) <= 1.0):
        raise ValueError(f"rho (dropout keep probability) must be a number in (0, 1], got {rho!r}")
    return float(rho)


@dataclass(frozen=True, kw_only=True)
class MonitorSpec:
    """One monitor configuration. LHD is always on; CH when ``tau`` is set; MCD when ``n`` and ``rho`` are.

    Parameters
    ----------
    tau : float in (0, 1) or None
        CH threshold.
    n : int in [2, 1000] or None
        MC-dropout samples.
    rho : float in (0, 1] or None
        MC-dropout keep probability (set together with ``n``).
    threshold : float or None
        Reject iff the monitor's score is above it; None (or 0): the paper's rule.

    Examples
    --------
    >>> MonitorSpec(tau=0.25, n=10, rho=0.9).name
    'lhd+ch+mcd:tau=0.25,n=10,rho=0.9'
    >>> parse_monitor_spec("lhd+mcd:rho=0.5,n=30") == MonitorSpec(n=30, rho=0.5)
    True
    """

    tau: float | None = None
    n: int | None = None
    rho: float | None = None
    threshold: float | None = None

    def __post_init__(self) -> None:
        if self.threshold is not None:  # the paper's threshold 0 is the default: one name per configuration
            t = _threshold(self.threshold)
            object.__setattr__(self, "threshold", None if t == 0.0 else t)
        if self.tau is not None:
            object.__setattr__(self, "tau", validate_tau(self.tau))
        if (self.n is None) != (self.rho is None):
            raise ValueError(f"MCD needs both n and rho, got n={self.n!r}, rho={self.rho!r}")
        if self.n is not None:
            object.__setattr__(self, "n", validate_n(self.n))
            object.__setattr__(self, "rho", validate_rho(self.rho))

    @property
    def uses_ch(self) -> bool:
        return self.tau is not None

    @property
    def uses_mcd(self) -> bool:
        return self.n is not None

    @property
    def kind(self) -> str:
        """``lhd``, ``lhd+ch``, ``lhd+mcd`` or ``lhd+ch+mcd``."""
        return "lhd" + ("+ch" if self.uses_ch else "") + ("+mcd" if self.uses_mcd else "")

    @property
    def name(self) -> str:
        """Canonical name; ``parse_monitor_spec(spec.name) == spec``."""
        params = []
        if self.tau is not None:
            params.append(f"tau={self.tau!r}")
        if self.n is not None:
            params += [f"n={self.n}", f"rho={self.rho!r}"]
        if self.threshold is not None:
            params.append(f"{THRESHOLD}={self.threshold!r}")
        return self.kind + (":" + ",".join(params) if params else "")

    @property
    def base(self) -> MonitorSpec:
        """The same configuration at the default threshold."""
        return MonitorSpec(tau=self.tau, n=self.n, rho=self.rho)

    @property
    def walk(self) -> str:
        """The paper's monitors walk the candidates by hazard rank."""
        return HAZARD

    def __str__(self) -> str:
        return self.name

    @classmethod
    def from_paper_row(cls, samples: float, threshold: float, dropout_rate: float) -> MonitorSpec:
        """The spec of a row of the paper's results CSV (``Samples MCD``, ``Threshold``,
        ``Dropout rate``; ``-1`` means not used)."""
        tau = None if threshold == -1 else float(threshold)
        if (samples == -1) != (dropout_rate == -1):
            raise ValueError(f"samples and dropout rate: both used or both -1, got {samples}, {dropout_rate}")
        if samples == -1:
            return cls(tau=tau)
        if float(samples) != int(samples):
            raise ValueError(f"samples must be an integer, got {samples!r}")
        return cls(tau=tau, n=int(samples), rho=float(dropout_rate))


_PARAMS = {"lhd": (), "lhd+ch": ("tau",), "lhd+mcd": ("n", "rho"), "lhd+ch+mcd": ("tau", "n", "rho")}
PAPER_COMPONENTS = frozenset({"lhd", "ch", "mcd"})


def _threshold(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(float(value)):
        raise ValueError(f"threshold must be a finite number, got {value!r}")
    return float(value)


def _format(value: Any) -> str:
    return repr(value) if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class GenericSpec:
    """A configuration of a registered monitor (``el.monitors.registry``): ``kind:key=value,...``.

    ``params`` holds the converted parameters in the registry's order (``threshold`` last).

    Examples
    --------
    >>> GenericSpec("msp", (("threshold", 0.5),)).name
    'msp:threshold=0.5'
    """

    kind: str
    params: tuple[tuple[str, Any], ...] = ()

    @property
    def name(self) -> str:
        return self.kind + (":" + ",".join(f"{k}={_format(v)}" for k, v in self.params) if self.params else "")

    @property
    def threshold(self) -> float | None:
        return dict(self.params).get(THRESHOLD)

    @property
    def walk(self) -> str:
        """The decision loop's walk order (``el.monitors.walk``): ``hazard`` unless ``walk=score``."""
        return str(dict(self.params).get(WALK, HAZARD))

    @property
    def base(self) -> GenericSpec:
        """The same configuration at the monitor's default threshold."""
        return GenericSpec(self.kind, tuple((k, v) for k, v in self.params if k != THRESHOLD))

    def kwargs(self) -> dict[str, Any]:
        """The monitor's constructor keywords (the walk is the decision loop's, not the monitor's)."""
        return {k: v for k, v in self.params if k != WALK}

    def __str__(self) -> str:
        return self.name


AnySpec = MonitorSpec | GenericSpec


def _bad(text: str, why: str) -> ValueError:
    return ValueError(f"bad monitor spec {text!r}: {why}; {VALID_FORMS}")


def parse_monitor_spec(text: str | AnySpec | None) -> AnySpec | None:
    """Parse a monitor name; ``"none"`` (or None) gives None (no runtime monitor).

    The paper's monitors (``lhd``, ``ch``, ``mcd`` components) give a :class:`MonitorSpec`: case and
    spaces are ignored, the components may come in any order (``lhd`` first in the canonical name),
    the parameters too, but every parameter of the kind is required. Any other name is looked up in
    the monitor registry (built-ins and the ``uav_el.monitors`` entry points) and gives a
    :class:`GenericSpec`; its values keep their case (file paths). Every monitor takes
    ``threshold=X``; a registered one also ``walk=score`` (``el.monitors.walk``).

    Raises
    ------
    ValueError
        With the reason and the valid forms.
    """
    if text is None or isinstance(text, MonitorSpec | GenericSpec):
        return text
    if not isinstance(text, str):
        raise ValueError(f"a monitor spec must be a string, got {type(text).__name__}; {VALID_FORMS}")
    raw = "".join(text.split())
    if raw.lower() == NONE:
        return None
    head, sep, tail = raw.partition(":")
    head = head.lower()
    parts = head.split("+")
    if not set(parts) & PAPER_COMPONENTS:
        return _parse_registered(text, head, tail if sep else "")
    clean = raw.lower()
    head, sep, tail = clean.partition(":")
    if "lhd" not in parts or len(set(parts)) != len(parts) or not set(parts) <= PAPER_COMPONENTS:
        raise _bad(text, f"unknown monitor {head!r}")
    kind = "lhd" + ("+ch" if "ch" in parts else "") + ("+mcd" if "mcd" in parts else "")
    expected = _PARAMS[kind]
    values = _key_values(text, kind, tail if sep else "", (*expected, THRESHOLD))
    missing = [k for k in expected if k not in values]
    if missing:
        raise _bad(text, f"{kind} needs {', '.join(missing)}")
    try:
        tau = float(values["tau"]) if "tau" in values else None
        rho = float(values["rho"]) if "rho" in values else None
        n = int(values["n"]) if "n" in values else None
        threshold = float(values[THRESHOLD]) if THRESHOLD in values else None
        if any(v is not None and not math.isfinite(v) for v in (tau, rho, threshold)):
            raise ValueError("parameters must be finite")
        return MonitorSpec(tau=tau, n=n, rho=rho, threshold=threshold)
    except ValueError as err:
        raise _bad(text, str(err)) from None


def _key_values(text: str, kind: str, tail: str, allowed: tuple[str, ...]) -> dict[str, str]:
    values: dict[str, str] = {}
    if not tail:
        return values
    for item in tail.split(","):
        key, eq, value = item.partition("=")
        key = key.lower()
        if not eq or not key or not value:
            raise _bad(text, f"parameter {item!r} is not key=value")
        if key not in allowed:
            raise _bad(text, f"{kind} takes no parameter {key!r}")
        if key in values:
            raise _bad(text, f"parameter {key!r} given twice")
        values[key] = value
    return values


def _parse_registered(text: str, kind: str, tail: str) -> GenericSpec:
    try:
        entry = monitor_entry(kind)
    except ValueError as err:  # unknown, or a plugin that failed to load
        raise _bad(text, str(err)) from None
    values = _key_values(text, kind, tail, (*entry.params, WALK, THRESHOLD))
    missing = [k for k in entry.required if k not in values]
    if missing:
        raise _bad(text, f"{kind} needs {', '.join(missing)}")
    params: list[tuple[str, Any]] = []
    try:
        for key, convert in (*entry.params.items(), (WALK, check_walk), (THRESHOLD, float)):
            if key == WALK and values.get(WALK, "").lower() == HAZARD:
                continue  # the default walk is left out of the canonical name
            if key in values:
                value = convert(values[key])
                if key == THRESHOLD:
                    value = _threshold(value)
                params.append((key, value))
    except (TypeError, ValueError) as err:
        raise _bad(text, str(err)) from None
    return GenericSpec(kind, tuple(params))


def monitor_name(spec: str | AnySpec | None) -> str:
    """Canonical name of a spec, ``"none"`` for no monitor."""
    parsed = parse_monitor_spec(spec)
    return NONE if parsed is None else parsed.name


PAPER_GRID: tuple[str, ...] = (
    MonitorSpec().name,
    *(MonitorSpec(tau=t).name for t in PAPER_TAUS),
    *(MonitorSpec(n=n, rho=r).name for n, r in product(PAPER_NS, PAPER_RHOS)),
    *(MonitorSpec(tau=t, n=n, rho=r).name for t, n, r in product(PAPER_TAUS, PAPER_NS, PAPER_RHOS)),
)
"""The paper's 21 configurations: LHD; LHD+CH (tau); LHD+MCD (n x rho); LHD+CH+MCD (tau x n x rho).
(The paper's CSV lists the MCD rows grouped by n first; ``MonitorSpec.from_paper_row`` maps them.)"""

DEMO_GRID: tuple[str, ...] = (
    "lhd",
    "lhd+ch:tau=0.25",
    "lhd+mcd:n=10,rho=0.9",
    "lhd+ch+mcd:tau=0.25,n=10,rho=0.9",
)
"""One configuration per kind, with the parameters the paper shows in its Table I because they
"always perform better or similar to other values" (tau = 0.25, N = 10, rho = 0.9); n = 10 is also
the cheaper MCD batch (overhead grows linearly with n)."""


def walk_of(name: str) -> str:
    """The walk order a configuration's decision loop uses (``walk=score`` in its spec, else hazard).

    A name that no longer parses here (a plugin monitor not installed on the machine reading a run) is
    read from its text."""
    try:
        return getattr(parse_monitor_spec(name), "walk", HAZARD)
    except ValueError:
        params = "".join(name.split()).lower().partition(":")[2].split(",")
        return "score" if "walk=score" in params else HAZARD
