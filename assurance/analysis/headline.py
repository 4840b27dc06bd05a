"""The README's headline results table, generated from a campaign run and kept between two markers.

`uav-el table RUN --readme README.md` writes it; `uav-el table RUN --check-readme README.md` (and a test
run by `make release-evidence`) fails when the README no longer shows what the run shows. The table is
about the deployed configuration (the requirement registry's `deployed_monitor`), one row per
perturbation, with the hashes of the model and of the calibration card it was made with.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from assurance.campaign import readouts
from assurance.files import atomic_write_bytes
from assurance.paths import card_path
from el.base.errors import UavElError
from el.base.hashing import sha256_file

BEGIN = "<!-- headline-table:begin (written by `uav-el table RUN --readme README.md`; do not edit by hand) -->"
END = "<!-- headline-table:end -->"


class HeadlineError(UavElError, ValueError):
    """A README without the markers, or a run without the deployed configuration."""


@dataclass(frozen=True, kw_only=True)
class Reproducibility:
    """How far the headline of a run made on another machine may lie from the README's (docs/results.md,
    "Reproducibility across machines").

    The network's float32 output and the brightness perturbation's float colour conversion differ in their last bits
    between CPUs (AVX2 or AVX-512 kernels of ONNX Runtime and OpenCV); such a difference moves a decision now and
    then to another candidate, one whose true hazard differs. ``decisions``: how many decisions per perturbation
    may move so; ``rounding``: the table's last printed digit. A moved decision changes a mean gain, and its
    bootstrap bounds, by at most 1/n of n scenes: the gains (G_CM, G_RM, G* and their 95% bounds) may differ by
    ``decisions / n + rounding``, recall and FP rate (pooled over the candidates) by ``rate``. ``counts``: how many
    unsafe landings per perturbation and column may differ (0: the header, the unsafe-landing counts, their rates
    and one-sided bounds must be equal: the safety claim itself is reproduced exactly or the check fails), and
    ``total`` how far a count column's sum over the perturbations may move (a table made to look safer moves it)."""

    decisions: int = 1
    rounding: float = 0.001
    rate: float = 0.01
    counts: int = 0
    total: int = 0

    def gain(self, n: int) -> float:
        """The tolerance of a gain over ``n`` scenes."""
        return self.decisions / max(1, n) + self.rounding

    def text(self, n: int) -> str:
        """What the report's "Reproduce" section says a rerun on another machine gives, for ``n`` scenes per
        perturbation."""
        return (f"On another machine of the same instruction set (the run's manifest names it: "
                f"versions.instruction_set) these commands must give the same unsafe-landing counts, rates and bounds; "
                f"a decision may now and then land on another candidate (ONNX Runtime's CPU kernels, chosen per "
                f"instruction set, differ in their last bits), so the safety gains may differ by up to "
                f"{self.gain(n):.3f} (one moved decision of {n} per perturbation, plus rounding) and recall and FP "
                f"rate by up to {self.rate:.2f}; on another instruction set a few decisions more may move "
                f"(docs/results.md, \"Reproducibility across machines\").")


REPRODUCIBILITY = Reproducibility()
"""The tolerance the README headline test (``tests/test_readme_headline.py``) and ``uav-el table --check-readme``
judge a run made on another machine of the same instruction set with."""
ACROSS_INSTRUCTION_SETS = Reproducibility(decisions=5, rate=0.10, counts=5, total=8)
"""The tolerance the README's headline (70 scenes per perturbation) judges a run on an instruction set with no
recorded table with, against a table recorded on another: up to 5 decisions of a perturbation on other candidates,
recall and FP rate within 0.10, and a count column's sum over the six perturbations within 8. Of the two pairs of
release runs measured on both (docs/results.md), the larger difference is the fused verifier's at 0.811: up to 2 of
70 in a cell, 3 (CM alone) and 5 (deployed) of 420 in a sum, and 0.079 in recall under fog; a newly
deployed configuration is recorded on one instruction set only, so the sums keep a margin over that pair. It
catches a table made to look safer (each deployed count 2 lower moves the sum by 12), not a last-bit difference."""
_NUMBER = re.compile(r"[+-]?\d+(?:\.\d+)?")
_ISA = re.compile(r"a CPU of instruction set `([^`]+)`")


def _ci(row: pd.Series, name: str) -> str:
    return f"{row[name]:+.3f} [{row[name + '_lo95']:+.3f}, {row[name + '_hi95']:+.3f}]"


def headline_markdown(run: str | Path, table: pd.DataFrame, deployed: str,
                      calibration_card: str | None = None) -> str:
    """The headline block for ``run`` (its results table ``table``) judged on ``deployed``."""
    rows = table[table["monitor"] == deployed]
    if rows.empty:
        raise HeadlineError(f"{run}: the run has no configuration {deployed!r} (the deployed monitor)")
    images = readouts.load_table(run, "images")
    mine = images[(images["monitor"] == deployed) & (images["fault"].fillna("") == "")]
    cm_unsafe = (readouts.core_hazard(mine) >= 1.0).groupby(mine["perturbation"]).sum().astype(int)
    man = readouts.read_manifest(run)
    isa = (man.get("versions") or {}).get("instruction_set")
    machine = f"a CPU of instruction set `{isa}`" if isa else "a CPU of an unrecorded instruction set"
    card = ""
    if calibration_card:
        path = card_path(calibration_card)
        card = f", calibration card `{path.name}` (sha256 `{sha256_file(path)[:12]}`)"
    lines = [
        f"Deployed configuration `{deployed}`{card}; model sha256 `{str(man['weights']['sha256'])[:12]}`; "
        f"{int(rows['images'].max())} test scenes per perturbation (severity {int(rows['severity'].iloc[0])}); "
        f"run on {machine}.",
        "",
        "| perturbation | unsafe landings, CM alone | unsafe landings, deployed | rate (one-sided 95% bound) "
        "| G_CM | G_RM [95%] | G* [95%] | recall / FP rate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for _, r in rows.iterrows():
        n = int(r["images"])
        lines.append(
            f"| {r['perturbation']} | {cm_unsafe.get(r['perturbation'], 0)} of {n} "
            f"| {int(round(r['unsafe_landing_rate'] * n))} of {n} "
            f"| {r['unsafe_landing_rate']:.3f} ({r['unsafe_landing_ub95']:.3f}) | {r['g_cm']:+.3f} "
            f"| {_ci(r, 'g_rm')} | {_ci(r, 'g_star')} | {r['recall']:.3f} / {r['fp_rate']:.3f} |")
    return "\n".join(lines) + "\n"


def _split(text: str, path: Path) -> tuple[str, str, str]:
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise HeadlineError(f"{path}: needs exactly one pair of headline markers ({BEGIN!r} ... {END!r})")
    head, rest = text.split(BEGIN)
    body, tail = rest.split(END)
    return head, body, tail


def _outside(x: str, y: str, tols: list[float]) -> bool:
    """Whether cell ``y``'s numbers differ in number from cell ``x``'s, or lie farther from them than ``tols`` (one
    per number, in order; numbers past the last are not compared)."""
    xs, ys = [float(v) for v in _NUMBER.findall(x)], [float(v) for v in _NUMBER.findall(y)]
    return len(xs) != len(ys) or any(abs(u - v) > t + 1e-9 for u, v, t in zip(xs, ys, tols, strict=False))


def headline_differences(expected: str, found: str, tolerance: Reproducibility = REPRODUCIBILITY) -> list[str]:
    """What keeps the headline block ``found`` (a run's) from reproducing ``expected`` (the README's) within
    ``tolerance``: one line per differing figure, naming the perturbation, the column and both values (empty: it
    reproduces). Identical blocks have no differences."""
    if expected == found:
        return []
    a, b = expected.strip("\n").splitlines(), found.strip("\n").splitlines()
    if len(a) != len(b):
        return [f"{len(a)} lines against {len(b)}"]
    out: list[str] = []
    sums = {1: [0, 0], 2: [0, 0]}  # the two unsafe-landing count columns, summed over the perturbations
    for old, new in zip(a, b, strict=True):
        if not (old.startswith("| ") and new.startswith("| ")) or old.startswith("| perturbation"):
            if old != new:
                out.append(f"{old!r} against {new!r}")
            continue
        cells_a, cells_b = old.strip("|").split("|"), new.strip("|").split("|")
        if len(cells_a) != len(cells_b) or len(cells_a) != 8 or cells_a[0] != cells_b[0]:
            out.append(f"{old!r} against {new!r}")
            continue
        pert = cells_a[0].strip()
        n = int(_NUMBER.findall(cells_a[1])[-1])
        for col, total in sums.items():
            total[0] += int(_NUMBER.findall(cells_a[col])[0])
            total[1] += int(_NUMBER.findall(cells_b[col])[0])
        for col, (x, y) in enumerate(zip(cells_a, cells_b, strict=True)):
            exact = tolerance.counts == 0 or col == 0 or (col == 3 and cells_a[2] == cells_b[2])
            if col < 4 and exact:  # the unsafe counts, the rate and its bound (which follow the deployed count)
                if x != y:
                    out.append(f"{pert}: column {col + 1} {x.strip()} against {y.strip()} (must be equal)")
                continue
            if col < 4:  # counts within ``counts`` decisions, the rate with them, its bound half as far again
                tols = ([tolerance.counts, 0] if col < 3 else
                        [tolerance.counts / n + tolerance.rounding, 1.5 * tolerance.counts / n + tolerance.rounding])
                note = f"within {tolerance.counts} of {n}"
            else:
                tol = tolerance.gain(n) if col < 7 else tolerance.rate
                tols, note = [tol] * len(_NUMBER.findall(x)), f"tolerance {tol:.4f}"
            if _outside(x, y, tols):
                out.append(f"{pert}: column {col + 1} {x.strip()} against {y.strip()} ({note})")
    if tolerance.counts:
        out += [f"column {col + 1}: {x} against {y} unsafe landings over the perturbations (within {tolerance.total})"
                for col, (x, y) in sums.items() if abs(x - y) > tolerance.total]
    return out


ALTERNATES = Path("docs") / "headline-runs"
"""Beside a README, the headline tables of release runs on other instruction sets (one file each, with the markers):
ONNX Runtime's convolutions differ in their last bits between AVX2 and AVX-512, and a few perturbed frames get
other candidates (docs/results.md, "Reproducibility across machines")."""


def reference_blocks(readme: str | Path) -> list[tuple[str, str]]:
    """(name, block) of each headline a release run may reproduce: the README's, then each recorded run of another
    instruction set (:data:`ALTERNATES` beside it)."""
    readme = Path(readme)
    out = [(readme.name, current_block(readme))]
    for path in sorted((readme.parent / ALTERNATES).glob("*.md")):
        out.append((str(path.relative_to(readme.parent)), current_block(path)))
    return out


def inconsistencies(block: str) -> list[str]:
    """The rows of a headline block whose rate is not its deployed count over its scenes (a count edited by hand
    without its rate): one line each; empty for a table as ``uav-el table`` writes it."""
    out = []
    for line in block.splitlines():
        cells = line.strip("|").split("|")
        if not line.startswith("| ") or line.startswith("| perturbation") or len(cells) != 8:
            continue
        deployed, rate = _NUMBER.findall(cells[2]), _NUMBER.findall(cells[3])
        if len(deployed) == 2 and rate and f"{int(deployed[0]) / max(1, int(deployed[1])):.3f}" != rate[0]:
            out.append(f"{cells[0].strip()}: rate {rate[0]} is not {cells[2].strip()}")
    return out


def instruction_set_of(block: str) -> str | None:
    """The instruction set a headline block's run was made on (its header names it); None: not named."""
    m = _ISA.search(block)
    return m.group(1) if m else None


@dataclass(frozen=True)
class Reproduction:
    """Which reference headline a run reproduces (``match``; None: none), whether only within
    :data:`ACROSS_INSTRUCTION_SETS` because no reference was recorded on the run's instruction set (``across``), and
    what differs from each reference it does not reproduce."""

    match: str | None
    across: bool
    differences: dict[str, list[str]]


def reproduced(found: str, references: list[tuple[str, str]], tolerance: Reproducibility = REPRODUCIBILITY,
               across: Reproducibility = ACROSS_INSTRUCTION_SETS) -> Reproduction:
    """The first reference block the run's ``found`` reproduces within ``tolerance``; failing that, and only when no
    reference was recorded on the run's own instruction set, the first one it reproduces within ``across`` (the
    instruction sets' names aside). A reference of the run's own instruction set must be reproduced within
    ``tolerance``."""
    differences: dict[str, list[str]] = {}
    for name, block in references:
        lines = headline_differences(block, found, tolerance)
        if not lines:
            return Reproduction(name, False, differences)
        differences[name] = lines
    isa = instruction_set_of(found)
    if isa is None or any(instruction_set_of(block) == isa for _, block in references):
        return Reproduction(None, False, differences)
    for name, block in references:
        other = instruction_set_of(block)
        if other is None:
            continue
        if broken := inconsistencies(block):  # only a table as written may lend its looser tolerance
            differences[f"{name} (another instruction set, {other})"] = broken
            continue
        renamed = _ISA.sub(lambda _m, other=other: f"a CPU of instruction set `{other}`", found)
        lines = headline_differences(block, renamed, across)
        if not lines:
            return Reproduction(name, True, differences)
        differences[f"{name} (another instruction set, {other})"] = lines
    return Reproduction(None, False, differences)


def current_block(path: str | Path) -> str:
    """The block between the README's markers, as written."""
    return _split(Path(path).read_text(encoding="utf-8"), Path(path))[1].strip("\n") + "\n"


def write_block(path: str | Path, block: str) -> bool:
    """Put ``block`` between the markers of ``path``; True when the file changed."""
    p = Path(path)
    text = p.read_text(encoding="utf-8")
    head, old, tail = _split(text, p)
    new = f"{head}{BEGIN}\n{block.rstrip()}\n{END}{tail}"
    if new != text:
        atomic_write_bytes(p, new.encode("utf-8"))
    return new != text
