"""Which of a campaign's recorded task faults are the data's, and which its configuration's.

A bad frame (unreadable, mislabelled, a pose the flat-ground model cannot plan with) is a recorded fault
of that task: the campaign carries on and exits 0, the readouts say which. Any other fault (a monitor or
network that cannot run, a seed a generator refuses, a model file changed during the run) would fault
every task alike and leave the readouts measuring nothing: the campaign exits 2 and says so.
"""

from __future__ import annotations

from collections.abc import Sequence

DATA_FAULTS = ("DataError", "LabelColourError")
"""Exception names of the faults a frame's own data causes (the fault text starts ``Name: ...``)."""


def is_data_fault(fault: str) -> bool:
    """Whether a recorded fault (``"ExceptionName: message"``) is the data's rather than the configuration's."""
    return fault.split(":", 1)[0].strip() in DATA_FAULTS


def config_faults(faults: Sequence[str]) -> list[str]:
    """The ``"shard: fault"`` lines of a campaign summary that are not data faults."""
    return [f for f in faults if not is_data_fault(f.split(": ", 1)[1] if ": " in f else f)]


def config_fault_line(faults: Sequence[str]) -> str:
    """The one error line for a campaign whose tasks faulted for a configuration reason."""
    bad = config_faults(faults)
    return (f"{len(bad)} task(s) faulted for a configuration reason, not their data (first: {bad[0]}); their "
            "shards record the fault: fix the configuration and run into a new --out folder")
