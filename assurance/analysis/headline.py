"""The README's headline results table, generated from a campaign run and kept between two markers.

`uav-el table RUN --readme README.md` writes it; `uav-el table RUN --check-readme README.md` (and a test
run by `make release-evidence`) fails when the README no longer shows what the run shows. The table is
about the deployed configuration (the requirement registry's `deployed_monitor`), one row per
perturbation, with the hashes of the model and of the calibration card it was made with.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from assurance.campaign import readouts
from assurance.files import atomic_write_bytes
from el.errors import UavElError
from el.hashing import sha256_file

BEGIN = "<!-- headline-table:begin (written by `uav-el table RUN --readme README.md`; do not edit by hand) -->"
END = "<!-- headline-table:end -->"


class HeadlineError(UavElError, ValueError):
    """A README without the markers, or a run without the deployed configuration."""


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
    card = ""
    if calibration_card:
        from assurance.paths import card_path

        path = card_path(calibration_card)
        card = f", calibration card `{path.name}` (sha256 `{sha256_file(path)[:12]}`)"
    lines = [
        f"Deployed configuration `{deployed}`{card}; model sha256 `{str(man['weights']['sha256'])[:12]}`; "
        f"{int(rows['images'].max())} test scenes per perturbation (severity {int(rows['severity'].iloc[0])}).",
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
