"""``uav-el fit-verifier``: train the candidate verifier (a CNN on the candidates' pixels) and write its record.

For any system: the system's network proposes the candidates of its own training and validation data, its label
set says which ground is forbidden, and the verifier learns that from the pixels (``el.monitors.verifier``). The
record (``--out``, JSON) and its ONNX network (beside it, ``.onnx``) are what ``verifier:model=FILE`` flies."""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import replace

from assurance.cli.arguments import fit_split_options
from assurance.cli.system_options import assessed, train_val_dirs
from assurance.errors import CommandError
from assurance.fitting.network_identity import network_record
from el.monitors.learned import LearnedMonitor

HELP = ("train the candidate verifier (a small CNN of its own on the full-resolution pixels around each candidate; "
        "diverse from the segmentation network) on the training split, select it on --val, and write its record and "
        "ONNX network")


def add_arguments(p: argparse.ArgumentParser) -> None:
    fit_split_options(p, out="verifier file to write (JSON; its ONNX network is written beside it)")
    p.add_argument("--steps", type=int, default=3000, help="training steps (default: %(default)s)")
    p.add_argument("--minutes", type=float,
                   help="stop training after this many minutes; the learning rate still decays over --steps, so a "
                        "run cut short ends before its rate is low (default: no limit)")
    p.add_argument("--batch", type=int, default=64, help="crops per step (default: %(default)s)")
    p.add_argument("--size", type=int, default=256,
                   help="crop side in pixels, a multiple of 16, large enough for the ground's texture to show "
                        "(a paver of a 4K frame survives 256 px, not 64; default: %(default)s)")
    p.add_argument("--margin", type=float, default=1.0,
                   help="context around the disc, in radii, 0 to 4 (default: %(default)s)")
    p.add_argument("--jitter", type=int, default=3, help="mined discs around each training candidate "
                                                         "(default: %(default)s)")
    p.add_argument("--lookalikes", type=int, default=0, metavar="N",
                   help="look-alike discs drawn per training scene where the network finds the ground valid but "
                        "the ground truth puts a forbidden pixel within the radius (default: %(default)s)")
    p.add_argument("--lr", type=float, default=1e-3, help="learning rate of the head (default: %(default)s)")
    p.add_argument("--eval-every", type=int, default=250, help="held-out AUROC every N steps (default: %(default)s)")
    p.add_argument("--views", type=int, default=1,
                   help="views of each training crop through the frozen encoder, the first as it is, the others "
                        "augmented (default: %(default)s)")
    p.add_argument("--augment", choices=("colour", "optics"), default="colour",
                   help="the augmented views' set: colour (a flip, a small zoom, colour balance, saturation, sensor "
                        "noise) or optics (and a lower resolution, a slight defocus, JPEG artefacts, a tone curve); "
                        "needs --views 2 or more for optics (default: %(default)s)")
    p.add_argument("--rank-weight", type=float, default=0.0, metavar="W",
                   help="weight of a ranking loss within each training scene: every unsafe crop scored above every "
                        "safe one of its scene, the order the score walk lands by (default: %(default)s, none)")
    p.add_argument("--frozen", choices=("encoder", "low"), default="encoder",
                   help="encoder: every encoder block keeps its ImageNet weights and the head learns (fast on 2 "
                        "cores); low: the blocks after 1/8 learn too (default: %(default)s)")
    p.add_argument("--anchor", type=float, default=0.0, metavar="W",
                   help="with --frozen low: weight of a pull of the learning blocks' features towards their ImageNet "
                        "features, so fine-tuning keeps what those are robust to (default: %(default)s, none)")
    p.add_argument("--deep", action=argparse.BooleanOptionalAction, default=True,
                   help="the encoder goes on to 1/32 (EfficientNet-Lite0's blocks 11-15, its most semantic "
                        "features; the crop side then a multiple of 32); --no-deep stops at 1/16 (default: deep)")
    p.add_argument("--fuse-layers", type=int, default=1,
                   help="3x3 convolutions over the fused 1/8 feature map, 1 to 6: more let each cell compare its "
                        "texture with its neighbours' (a street paved like the square it crosses; default: "
                        "%(default)s)")
    p.add_argument("--recall", type=float, default=0.95,
                   help="threshold: the largest with this recall of unsafe held-out candidates (0.95)")
    p.add_argument("--fuse-learned", metavar="FILE", nargs="?", const="",
                   help="also choose the fusion with the learned monitor (FILE; without one, the shipped model)")
    p.add_argument("--images", type=int, help="use the first N scenes of each split")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-pretrained", action="store_true",
                   help="start the encoder from random weights, not ImageNet's")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from assurance.fitting.verifier_fit import (
        VerifierFitOptions,
        fit_verifier,
    )  # deferred: pulls in torch; keeps fit-verifier --help light
    from assurance.fitting.verifier_train import TrainConfig  # deferred: torch; keeps fit-verifier --help light

    system = assessed(args)
    train_val_dirs(args, system.file)
    try:
        options = VerifierFitOptions(  # checked before the network loads
            core=system.core, jitter=args.jitter, lookalikes=args.lookalikes, recall=args.recall, images=args.images,
            command=shlex.join(["uav-el", *sys.argv[1:]]) if sys.argv[1:2] == ["fit-verifier"] else None,
            pretrained=not args.no_pretrained, progress=not (args.no_progress or getattr(args, "quiet", False)))
        cfg = TrainConfig(size=args.size, margin=args.margin, steps=args.steps, batch=args.batch, lr=args.lr,
                          eval_every=args.eval_every, minutes=args.minutes, seed=args.seed, threads=args.threads,
                          views=args.views, augment=args.augment, rank_weight=args.rank_weight, frozen=args.frozen,
                          anchor=args.anchor,
                          deep=args.deep, fuse_layers=args.fuse_layers)
        segmenter = system.segmenter(working_width=system.core.working_width)
        learned = None
        if args.fuse_learned is not None:
            learned = LearnedMonitor(labels=system.labels, model=args.fuse_learned or None)
            learned.check_network(segmenter)
        options = replace(options, learned=learned, weights=network_record(segmenter, system.model))
        doc = fit_verifier(args.data, args.val, segmenter, args.out, cfg=cfg, options=options)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    b = doc["body"]
    h = b["held_out"]
    print(f"verifier: held-out AUROC {h['auroc']:.3f} on {h['candidates']} candidates ({h['unsafe']} unsafe); "
          f"threshold {b['threshold']:.4g} (recall {h['recall']:.3f}, safe rejected {h['safe_rejected']:.3f}); "
          f"step {b['training']['selected_step']} of {b['training']['steps_run']}")
    if b.get("fusion"):
        f = b["fusion"]
        print(f"fused with the learned monitor: weight {f['weight']:g}, held-out AUROC {f['held_out']['auroc']:.3f} "
              f"(learned alone {f['learned_alone_auroc']:.3f}), threshold {f['threshold']:.4g}")
    print(f"verifier written to {args.out} and {args.out.with_suffix('.onnx')} (sha256 {doc['sha256'][:12]}...)")
    return 0
