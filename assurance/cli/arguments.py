"""Argument types and options shared by several sub-commands (argparse ``type=`` callables, option sets)."""

from __future__ import annotations

import argparse
from pathlib import Path

from el.segmentation.protocol import check_frame_scales


def frame_scales(text: str) -> tuple[float, ...]:
    """``--frame-scales 1,1.25``: the sizes the working-resolution frame is fed to the network at."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected factors like 1.25 or 1,1.25, got {text!r}") from None
    try:
        return check_frame_scales(values)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (e.g. 1.25 or 1,1.25)") from None


def model_option(p: argparse.ArgumentParser) -> None:
    """``--weights`` / ``--model``: the segmentation model a command runs (``system_options.load_model`` reads it)."""
    p.add_argument("--weights", "--model", dest="weights", metavar="MODEL",
                   help="segmentation model: a .pt weights file with its card, an .onnx file, or a registered "
                        "uav_el.models name (NAME or NAME:ARG); default: the system's network ([model] of the "
                        "system file; the shipped one without)")


def fit_split_options(p: argparse.ArgumentParser, out: str = "gate file to write (JSON)") -> None:
    """``--data``, ``--val`` and ``--out`` of a fit on train and validation splits (a frame gate's, a verifier's;
    ``system_options.train_val_dirs`` resolves the folders), and the model (``model_option``); ``out``: what
    ``--out`` writes."""
    p.add_argument("--data", help="training scenes (e.g. data/train); default: the system file's [data] train")
    p.add_argument("--val", help="validation scenes for the threshold (e.g. data/val); default: the system file's "
                                 "[data] val")
    p.add_argument("--out", required=True, type=Path, help=out)
    model_option(p)
