"""``uav-el export-onnx``: write a project network (the shipped one by default) as an ONNX file, checked."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from assurance.errors import CommandError
from el.base.imageio import read_image
from el.segmentation.factory import is_weights_file
from el.segmentation.onnx_engine import onnxruntime
from el.segmentation.weights import DEFAULT_WEIGHTS

HELP = "export the segmentation network to ONNX (opset stated), checked against torch under ONNX Runtime"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, required=True, help="the .onnx file to write")
    parser.add_argument("--model", help="a project .pt weights file with its card (default: the shipped network)")
    parser.add_argument("--opset", type=int, default=None, help="ONNX opset (13..21; default 17)")
    parser.add_argument("--frame", type=Path,
                        help="image to compare torch and ONNX Runtime on (default: a rendered synthetic scene)")
    parser.add_argument("--beside", action="store_true",
                        help="also write OUT.json binding the file to the weights, so Segmenter.load runs the network "
                             "under ONNX Runtime (OUT must be the weights file's name with .onnx)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def run(args: argparse.Namespace) -> int:
    from assurance.fitting.network.onnx_export import (
        DEFAULT_OPSET,
        export_onnx,
    )  # deferred: pulls in torch; keeps export-onnx --help light

    onnxruntime()  # the one-line install hint before anything is loaded
    if args.out.suffix != ".onnx":
        raise CommandError(f"{args.out}: --out must name a .onnx file")
    if args.model and not (is_weights_file(args.model) and str(args.model).endswith(".pt")):
        raise CommandError(f"--model {args.model}: a project .pt weights file expected (with its card beside it)")
    if args.beside:
        weights = Path(args.model) if args.model else DEFAULT_WEIGHTS
        if args.out.resolve() != weights.with_suffix(".onnx").resolve():
            raise CommandError(f"{args.out}: with --beside, --out must be {weights.with_suffix('.onnx')}")
    frame = None
    if args.frame:
        frame = read_image(args.frame)
    result = export_onnx(args.model or None, args.out, opset=args.opset or DEFAULT_OPSET, frame=frame,
                         beside=args.beside)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"file:     {result['path']}")
    print(f"sha256:   {result['sha256']}")
    print(f"opset:    {result['opset']}")
    print(f"source:   weights sha256 {result['source_weights_sha256']}")
    print("input:    float32 NCHW RGB in [0, 1], dynamic batch, height and width (>= 16); output logits (B, C, H, W)")
    print(f"classes:  {', '.join(result['classes'])}")
    for c in result["checks"]:
        print(f"check:    {c['size'][0]}x{c['size'][1]}: largest logit difference {c['max_logit_diff']:.3g}, "
              f"argmax differs on {c['argmax_differ']} of {c['pixels']} pixels "
              f"({c['argmax_differ_not_tie']} beyond a float tie)")
    return 0
