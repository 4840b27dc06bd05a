"""The work of ``uav-el train`` (its options: ``assurance.cli.train``)."""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from assurance.dataio.layouts import iter_samples
from assurance.errors import CommandError
from assurance.fitting.card_audit import record_audit
from assurance.fitting.network import data as D
from assurance.fitting.network.train_config import TrainConfig, steps_for_epochs
from assurance.fitting.network.training import RunOptions, resolve_device, train
from assurance.fitting.training_curve import curve_path, write_training_curve
from assurance.progress import progress
from el.geometry.config import check_seed
from el.segmentation.architectures import arch_from_dict, default_arch
from el.segmentation.protocol import EvalProtocol
from el.segmentation.weights import WeightsError, read_card


def run(args: argparse.Namespace) -> int:
    if args.threads is not None and args.threads < 1:
        raise CommandError(f"--threads must be >= 1, got {args.threads}")
    if args.prefetch is not None and args.prefetch < 0:
        raise CommandError(f"--prefetch must be >= 0, got {args.prefetch}")
    check_seed(args.seed, "--seed")
    try:
        device = resolve_device(args.device)
    except ValueError as exc:
        raise CommandError(f"--device: {exc}") from exc
    prefetch = args.prefetch if args.prefetch is not None else (0 if device.type == "cpu" else 4)
    steps = args.steps if args.steps is not None else 1500
    if args.epochs is not None:
        images = sum(1 for _ in iter_samples(args.data))
        steps = steps_for_epochs(images, args.epochs, args.batch)
    arch, init_sha = _architecture(args)
    arch_kwargs = arch.to_dict()
    if args.widths is not None:
        if arch.name != "msdlite":
            raise CommandError(f"--widths applies to --arch msdlite, not {arch.name}")
        arch_kwargs["widths"] = args.widths
    if args.dropout is not None:
        arch_kwargs["dropout"] = args.dropout
    try:
        config = TrainConfig(
            steps=steps, batch=args.batch, crop=args.crop, hd_pixels=int(round(args.hd_crops * 256 * 256)),
            hd_crop_min=args.hd_crop[0], hd_crop_max=args.hd_crop[1], lr=args.lr, eval_every=args.eval_every,
            checkpoint_every=args.checkpoint_every, seed=args.seed, working_width=args.working_width,
            arch=arch_from_dict(arch_kwargs), baseline_pixels=0 if args.no_baseline else 200_000,
            eval_protocol=EvalProtocol(working_width=args.working_width, hd_patch_size=args.hd_eval_size,
                                       hd_patches=args.hd_eval_patches, frame_flip=args.frame_flip,
                                       frame_scales=args.frame_scales, frame_pooling=args.frame_pooling),
            init_sha256=init_sha, loss=args.loss, encoder_lr_scale=args.encoder_lr_scale,
            freeze_early_steps=args.freeze_early_steps,
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    cache_dir = None if args.no_cache else (args.cache_dir or D.default_cache_dir())
    # tqdm.write keeps log lines apart from a progress bar on the same stream.
    log = None if args.quiet else (lambda msg: tqdm.write(msg, file=sys.stderr))
    bar = functools.partial(progress, enabled=not args.quiet)
    options = RunOptions(resume=args.resume, cache_dir=cache_dir, checkpoint_file=args.checkpoint, threads=args.threads,
                         init_weights=args.init, device=device, stop_at=args.stop_at, prefetch=prefetch)
    card = train(args.data, args.out, val_dir=args.val, config=config, options=options, progress=bar, log=log,
                 on_eval=lambda history: write_training_curve(history, curve_path(args.out)))
    _print_summary(card, args.out, config.steps)
    if args.val is not None and not args.no_audit:

        record_audit(args.out, args.val, args.threads, args.quiet)
    return 0


def _architecture(args: argparse.Namespace) -> tuple[Any, str | None]:
    """The network to train (``--arch``, or the ``--init`` parent's) and the parent's SHA-256 (None: none)."""

    arch = default_arch(args.arch or "lite0")
    if args.init is None:
        return arch, None
    try:
        init_card = read_card(args.init)
    except WeightsError as exc:
        raise CommandError(str(exc)) from exc
    try:
        arch = arch_from_dict(init_card["architecture"])
    except ValueError as exc:
        raise CommandError(f"{args.init}: {exc}") from exc
    if args.arch is not None and args.arch != arch.name:
        raise CommandError(f"--arch {args.arch}: the --init weights are {arch.name}")
    return arch, init_card["weights_sha256"]


def _print_summary(card: dict[str, Any], out: Path, steps: int) -> None:
    """What the run wrote and its figures: weights, curve, steps and timing, validation mIoU, baseline."""
    training = card["training"]
    print(f"weights: {out} (sha256 {card['weights_sha256']})")
    if training.get("history"):
        print(f"training curve: {write_training_curve(training['history'], curve_path(out))}")
    print(f"steps: {steps}, best step: {training.get('best_step')}, "
          f"{training['seconds_per_step']:.2f} s/step, training {training['train_seconds']:.0f} s")
    ev = card.get("evaluation")
    if ev:
        wr, hd = ev["working_resolution"]["miou"], ev["hd_patches"]["miou"]
        print(f"validation mIoU: working resolution {wr:.4f}, HD patches {hd if hd is None else f'{hd:.4f}'}")
    if card.get("baseline"):
        print(f"per-pixel baseline mIoU: {card['baseline']['miou']:.4f} "
              f"(CNN - baseline = {card['baseline']['miou_gap_to_cnn']:.4f})")
