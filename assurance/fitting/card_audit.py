"""The candidate audit of a weights file: run it, record it in the model card, say it in one line.

Shared by ``uav-el train`` (audit after training) and ``uav-el model-card`` (print, verify, re-issue).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from assurance.fitting.candidate_audit import candidate_audit
from assurance.fitting.separation import describe_separation
from assurance.progress import progress
from el.segmentation.factory import load_model
from el.segmentation.weights import read_card


def fmt_figure(value: Any) -> str:
    """A figure with 4 decimals, or "-" when it is missing."""
    return "-" if value is None else f"{value:.4f}"


def describe_audit(a: dict[str, Any]) -> str:
    """The recorded candidate audit ``a`` as the text ``model-card`` and ``train`` print."""
    text = (f"{a['unsafe']} of {a['candidates']} core-model candidates truly unsafe ({fmt_figure(a['unsafe_share'])}) "
            f"on {a['images']} clean scenes of {a['data']}; top-ranked unsafe in {fmt_figure(a['top_unsafe_share'])} "
            f"of the scenes with a candidate")
    causes = a.get("unsafe_by_class")
    if causes:
        text += ("; mostly " + ", ".join(f"{name} in {n}" for name, n in causes.items())
                 + f"; median forbidden share of an unsafe disc {fmt_figure(a.get('median_forbidden_share'))}")
    if a.get("separation"):
        text += "\n              separation: " + describe_separation(a["separation"])
    return text


def audit(path: Path, data: Path | None, threads: int | None, quiet: bool) -> dict[str, Any]:
    """The candidate audit of a weights file on its validation data (or ``data``)."""
    card = read_card(path)
    # Where the card's figures come from (a re-issued card: this machine's copy), else the training's val.
    evaluated_on = (card.get("evaluation") or {}).get("data")
    selected_on = ((card.get("training") or {}).get("data") or {}).get("val")
    folder = data or Path((evaluated_on or selected_on or {}).get("path", ""))
    if not str(folder) or not folder.is_dir():
        raise ValueError(f"{path}: no validation folder to audit (give --data)")
    return candidate_audit(load_model(path, threads=threads), folder,
                           progress=functools.partial(progress, enabled=not quiet))


def record_audit(path: Path, data: Path | None, threads: int | None, quiet: bool) -> dict[str, Any]:
    """Run the candidate audit, write it into the card's ``candidates`` section and print it."""
    from assurance.fitting.network.weights_io import write_card  # deferred: imports torch (the train extra)

    result = audit(path, data, threads, quiet)
    card = read_card(path)
    card["candidates"] = result
    write_card(path, card)
    print(f"candidates: {describe_audit(result)}")
    return result
