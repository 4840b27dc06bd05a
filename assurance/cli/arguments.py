"""Argument types shared by several sub-commands (argparse ``type=`` callables)."""

from __future__ import annotations

import argparse


def frame_scales(text: str) -> tuple[float, ...]:
    """``--frame-scales 1,1.25``: the sizes the working-resolution frame is fed to the network at."""
    from el.segmentation.protocol import check_frame_scales

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected factors like 1.25 or 1,1.25, got {text!r}") from None
    try:
        return check_frame_scales(values)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (e.g. 1.25 or 1,1.25)") from None
