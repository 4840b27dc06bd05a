"""The training curve of a segmentation run as a PNG: loss and validation mIoU (both scales) per step."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from assurance.files import atomic_write_bytes


def curve_path(weights_path: str | Path) -> Path:
    """Where ``uav-el train`` draws the curve of a weights file: ``<weights stem>.curve.png`` beside it."""
    weights_path = Path(weights_path)
    return weights_path.with_name(weights_path.stem + ".curve.png")


def write_training_curve(history: list[dict[str, Any]], out: str | Path) -> Path:
    """Draw the mean training loss and the validation mIoU of each evaluation; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [h["step"] for h in history]
    fig, ax = plt.subplots(figsize=(7, 3.6), dpi=110)
    ax.plot(steps, [h["loss"] for h in history], "o-", color="0.35", label="training loss (mean since last point)")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.grid(alpha=0.3)
    handles = ax.get_lines()
    if any("val_miou_working" in h for h in history):
        right = ax.twinx()
        for key, label, colour in (("val_miou_working", "val mIoU, working resolution", "tab:blue"),
                                   ("val_miou_hd", "val mIoU, HD patches", "tab:orange")):
            pts = [(h["step"], h[key]) for h in history if h.get(key) is not None]
            if pts:
                right.plot(*zip(*pts, strict=True), "s-", color=colour, label=label)
        right.set_ylabel("mIoU")
        handles = handles + right.get_lines()
    ax.legend(handles=handles, labels=[h.get_label() for h in handles], loc="lower left", fontsize=8)
    ax.set_title("segmentation training")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    out = Path(out)
    atomic_write_bytes(out, buf.getvalue())
    return out
