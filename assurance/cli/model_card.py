"""``uav-el model-card``: print a weights file's model card, or verify its figures (``--verify``)."""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path
from typing import Any

from assurance.cli.arguments import frame_scales
from assurance.errors import CommandError
from assurance.fitting.card_audit import audit, describe_audit, record_audit
from assurance.fitting.card_audit import fmt_figure as _fmt
from assurance.progress import progress
from el.classes.labels import CLASS_NAMES
from el.segmentation.protocol import EvalProtocol
from el.segmentation.weights import DEFAULT_WEIGHTS, WeightsError, read_card

HELP = "print the segmentation model card; --verify recomputes its figures from the weights and data"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--weights", type=Path,
                        help="weights file (default: the shipped el/segmentation/weights/model.pt)")
    parser.add_argument("--verify", action="store_true",
                        help="check the SHA-256, recompute IoU / confusion on the validation data, compare")
    parser.add_argument("--data", type=Path, help="validation set for --verify (default: the folder in the card)")
    parser.add_argument("--train", type=Path, help="training set: with --verify, also refit and check the baseline")
    parser.add_argument("--audit-candidates", action="store_true",
                        help="measure the share of truly unsafe core-model candidates on the clean validation "
                             "scenes and record it in the card")
    parser.add_argument("--reissue", action="store_true",
                        help="recompute the card's figures (evaluation, candidate audit; baseline with --train) on "
                             "this machine's copy of the scenes given by --data and write them into the card")
    parser.add_argument("--frame-flip", choices=("on", "off"),
                        help="with --reissue: segment frames as the mean softmax of the frame and its mirror image "
                             "(on) or the frame alone (off); recorded in the card, which the flight code follows")
    parser.add_argument("--frame-scales", type=frame_scales, metavar="S[,S...]",
                        help="with --reissue: feed the working-resolution frame to the network resized by these "
                             "factors (e.g. 1.25, or 1,1.25) and average the softmax; recorded in the card, which the "
                             "flight code follows")
    parser.add_argument("--frame-pooling", choices=("area", "conservative"),
                        help="with --reissue: how a softmax of a frame fed at x>1 comes back to the working "
                             "resolution: area (footprint mean) or conservative (keeps any forbidden class a source "
                             "pixel shows); recorded in the card, which the flight code follows")
    parser.add_argument("--hd-patches", type=int, metavar="N",
                        help="with --reissue: HD validation patches per frame (default: as recorded in the card)")
    parser.add_argument("--tolerance", type=float, default=0.002,
                        help="IoU and separation-AUROC tolerance of --verify (default 0.002: a CPU's kernels differ "
                             "in their last bits between instruction sets)")
    parser.add_argument("--threads", type=int, help="torch CPU threads")
    parser.add_argument("--json", action="store_true", help="print the card (or the verification) as JSON")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def _print_card(card: dict[str, Any], path: Path) -> None:
    print(f"weights:      {path}")
    print(f"sha256:       {card['weights_sha256']}")
    print(f"parameters:   {card.get('parameters')}")
    arch = card["architecture"]
    print("architecture: " + ", ".join(f"{k}={v}" for k, v in arch.items()))
    training = card.get("training") or {}
    for split, ident in (training.get("data") or {}).items():
        if ident:
            print(f"{split + ' data:':<14}{ident['path']} ({ident['images']} images, sha256 {ident['sha256'][:16]}...)")
    if training:
        print(f"training:     seed {training.get('seed')}, {training.get('steps')} steps, best step "
              f"{training.get('best_step')}, {training.get('train_seconds')} s "
              f"({training.get('seconds_per_step')} s/step, {training.get('threads')} threads)")
        parent = training.get("init")
        if parent:
            print(f"warm start:   from {parent['weights_sha256'][:16]}... ({parent.get('total_steps')} steps): "
                  f"{training.get('total_steps')} steps in all")
    ev = card.get("evaluation")
    if not ev:
        print("evaluation:   none (trained without validation data)")
        return
    wr, hd = ev["working_resolution"], ev["hd_patches"]
    print(f"evaluation:   {ev['frames']} frames at working resolution{describe_frames(ev['protocol'])}, "
          f"{ev['patches']} HD patches "
          f"({ev['protocol']['hd_patch_size']} px)")
    print(f"  {'class':<16}{'IoU working':>12}{'IoU HD':>10}")
    for name in CLASS_NAMES:
        print(f"  {name:<16}{_fmt(wr['per_class_iou'].get(name)):>12}{_fmt(hd['per_class_iou'].get(name)):>10}")
    print(f"  {'mIoU':<16}{_fmt(wr['miou']):>12}{_fmt(hd['miou']):>10}")
    base = card.get("baseline")
    if base:
        print(f"baseline:     {base['name']}: mIoU {_fmt(base['miou'])} "
              f"(CNN - baseline = {_fmt(base.get('miou_gap_to_cnn'))})")
    cands = card.get("candidates")
    if cands:
        print(f"candidates:   {describe_audit(cands)}")


def describe_frames(protocol: dict[str, Any]) -> str:
    """How the card has frames segmented, as a parenthesis ('' for the frame alone, as it is)."""
    try:
        read = EvalProtocol.from_dict(protocol)
    except ValueError as exc:
        return f" (frames: {exc})"
    scales, parts = list(read.frame_scales), []
    if scales != [1.0]:
        parts.append("fed to the network at x" + ", x".join(f"{s:g}" for s in scales)
                     + (", softmax averaged" if len(scales) > 1 else ", softmax brought back")
                     + (" conservatively" if read.frame_pooling == "conservative" else ""))
    if read.frame_flip:
        parts.append("mean of the frame and its mirror image")
    return f" ({'; '.join(parts)})" if parts else ""


def _auroc(audit_result: dict[str, Any]) -> float | None:
    """The recorded separation AUROC, rounded (it is recomputed bit for bit, but JSON rounds floats)."""
    sep = (audit_result.get("separation") or {}).get("scores", {}).get("max_forbidden_probability")
    return None if not sep or sep["auroc"] is None else round(sep["auroc"], 9)


def audit_agreement(recorded: dict[str, Any], again: dict[str, Any], tolerance: float) -> tuple[bool, str]:
    """Whether a recomputed candidate audit reproduces the card's: the counts exactly, the separation AUROC within
    ``tolerance`` (a CPU's kernels differ in their last bits between instruction sets, and a candidate may move);
    and the line that says so, with both AUROCs where they differ."""
    keys = ("images", "candidates", "unsafe", "images_without_candidate")
    was, now = _auroc(recorded), _auroc(again)
    same_evidence = was is None or (now is not None and abs(now - was) <= tolerance)
    auroc = "" if was is None else f"separation AUROC recorded {was:.6f}, recomputed {now}"
    if all(again[k] == recorded[k] for k in keys) and same_evidence:
        within = "" if now == was else f" ({auroc}, within --tolerance {tolerance:g})"
        return True, f"candidate audit: {again['unsafe']} of {again['candidates']} unsafe, as recorded{within}"
    return False, ("candidate audit: recorded " + ", ".join(f"{k}={recorded[k]}" for k in keys) + "; recomputed "
                   + ", ".join(f"{k}={again[k]}" for k in keys) + (f"; {auroc}" if auroc else "")
                   + f" (--tolerance {tolerance:g})")


def _reissue(path: Path, args: argparse.Namespace) -> int:
    from assurance.fitting.network.card import (
        ProtocolChanges,
        reissue_card,
    )  # deferred: pulls in torch; keeps model-card --help light

    if args.verify:
        raise CommandError("--reissue and --verify do not go together: re-issue first, then verify")
    if args.data is None:
        raise CommandError("--reissue needs --data: the validation scenes to recompute the figures on")
    try:
        flip = None if args.frame_flip is None else args.frame_flip == "on"
        changes = ProtocolChanges(frame_flip=flip, hd_patches=args.hd_patches, frame_scales=args.frame_scales,
                                  frame_pooling=args.frame_pooling)
        card = reissue_card(path, val_dir=args.data, train_dir=args.train, threads=args.threads,
                            progress=functools.partial(progress, enabled=not args.quiet), changes=changes)
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    ev, before = card["evaluation"], card["evaluation"]["reissued"]
    print(f"{path}: evaluation re-issued on {args.data} ({ev['data']['sha256'][:16]}...): mIoU working "
          f"{_fmt(ev['working_resolution']['miou'])} (was {_fmt(before['miou_working'])}), HD patches "
          f"{_fmt(ev['hd_patches']['miou'])} (was {_fmt(before['miou_hd'])})")
    if card.get("baseline"):
        print(f"baseline: mIoU {_fmt(card['baseline']['miou'])} "
              f"(CNN - baseline = {_fmt(card['baseline']['miou_gap_to_cnn'])})")
    record_audit(path, args.data, args.threads, args.quiet)
    return 0


def run(args: argparse.Namespace) -> int:
    path = args.weights or DEFAULT_WEIGHTS
    for given, flag in ((args.frame_flip, "--frame-flip"), (args.hd_patches, "--hd-patches"),
                        (args.frame_scales, "--frame-scales"), (args.frame_pooling, "--frame-pooling")):
        if given is not None and not args.reissue:
            raise CommandError(f"{flag} changes the card's protocol: use it with --reissue --data VAL")
    if args.reissue:
        return _reissue(path, args)
    if args.audit_candidates and not args.verify:
        record_audit(path, args.data, args.threads, args.quiet)
        return 0
    if not args.verify:
        if not path.exists():
            raise WeightsError(f"{path}: weights file not found")
        card = read_card(path)
        if args.json:
            print(json.dumps(card, indent=2))
        else:
            _print_card(card, path)
        return 0
    from assurance.fitting.network.card import verify_card  # deferred: torch; keeps model-card --help light

    result = verify_card(path, val_dir=args.data, train_dir=args.train, threads=args.threads,
                         iou_tol=args.tolerance, progress=functools.partial(progress, enabled=not args.quiet))
    recorded = read_card(path).get("candidates")
    if recorded and result.ok:
        again = audit(path, args.data, args.threads, args.quiet)
        ok, line = audit_agreement(recorded, again, args.tolerance)
        (result.checks if ok else result.problems).append(line)
    if args.json:
        print(json.dumps({"weights": str(path), "ok": result.ok, "checks": result.checks,
                          "problems": result.problems}, indent=2))
    else:
        for line in result.checks:
            print(f"ok        {line}")
        for line in result.problems:
            print(f"MISMATCH  {line}")
        print("model card verified" if result.ok else f"model card NOT verified: {len(result.problems)} problem(s)")
    return 0 if result.ok else 1
