"""``uav-el land``: decide where to land for one frame, and say why.

Two pipelines (docs/architecture.md section 3.7):
- ground truth: ``uav-el land --labels LABELS.png [--image IMAGE.png]`` runs the CM on the label
  map (a perfect segmentation), without a monitor; the image is only for drawing;
- model: ``uav-el land IMAGE.png [--monitor SPEC]`` segments the image with the shipped CNN (or
  ``--weights``), ranks the candidates and walks them with the runtime monitor (el.flight.pipeline).

Exit codes: 0 a decision was made (land or default action); 2 bad input or options (one line naming
the file and the problem); 3 the flight path hit a fault (e.g. missing weights) and took the
default action, which is still written and drawn."""

from __future__ import annotations

import argparse
from pathlib import Path

from el.base.deadline import DEFAULT_TIME_BUDGET_S
from el.base.imageio import MAX_PIXELS
from el.geometry.camera import CAMERAS, MAX_ROLL_DEG, Pose
from el.geometry.config import MODES, CoreConfig

WORK = "assurance.cli.land_run"
"""Its work, imported only when it runs (heavy imports at its top: --help stays light)."""

HELP = "decide where to land for one frame (model pipeline, or the ground-truth pipeline with --labels)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("image_arg", nargs="?", metavar="IMAGE",
                        help="input image (the model pipeline; with --labels, the image to draw on)")
    parser.add_argument("--labels", type=Path, metavar="LABELS.png",
                        help="colour label map in the system's label palette ([labels]; UAVid's by default): run the "
                             "ground-truth pipeline on it")
    parser.add_argument("--label-encoding", choices=("rgb", "ids"), help="how --labels holds its classes: rgb "
                        "(the palette's colours) or ids (8-bit class ids); default: the system file's [data] "
                        "label_encoding (test, else val, else train split), else rgb")
    parser.add_argument("--id-offset", type=int, metavar="N", help="with --label-encoding ids: the value of class "
                        "id 0 (default: the system file's, else 0)")
    parser.add_argument("--image", type=Path, metavar="IMAGE.png", help="image to draw the overlay on")
    parser.add_argument("--json", type=Path, metavar="OUT.json", help="write the decision as JSON")
    parser.add_argument("--overlay", type=Path, metavar="OUT.png", help="draw the decision into a PNG")
    parser.add_argument("--log", type=Path, metavar="FILE", help="append the decision's record to this flight log "
                        "(el.flight.flightlog, JSON lines; model pipeline; uav-el in-service reads it)")
    parser.add_argument("--height", type=float, default=None, metavar="M",
                        help=f"flight height above the ground in metres (default: the system file's, else "
                             f"{Pose().height_m})")
    parser.add_argument("--pitch", type=float, default=None, metavar="DEG",
                        help=f"camera pitch below the horizon in degrees (default: the system file's, else "
                             f"{Pose().pitch_deg})")
    parser.add_argument("--roll", type=float, default=0.0, metavar="DEG",
                        help=f"camera roll in degrees, not modelled: accepted within +-{MAX_ROLL_DEG:g} as a pose "
                             "error, refused beyond (default: %(default)s)")
    parser.add_argument("--camera", choices=sorted(CAMERAS), default=None,
                        help="camera preset (default: the system file's camera, else phantom4); the options below "
                             "override its values")
    parser.add_argument("--sensor-width", type=float, metavar="MM", help="sensor width in millimetres")
    parser.add_argument("--sensor-height", type=float, metavar="MM",
                        help="sensor height in millimetres (optional: when the image is taller than the sensor's "
                             "proportions it spans the sensor's height)")
    lens = parser.add_mutually_exclusive_group()
    lens.add_argument("--focal", type=float, metavar="MM", help="focal length in millimetres")
    lens.add_argument("--hfov", type=float, metavar="DEG", help="horizontal field of view in degrees")
    parser.add_argument(
        "--mode", choices=MODES, default=None,
        help="valid pixels: exact disc, or the paper's stripes and squares (default: exact)",
    )
    parser.add_argument("--working-width", type=int, default=None, metavar="PX",
                        help="working resolution width: the frame is resized to it, aspect kept (default: the "
                             f"system file's [model] working_width, else {CoreConfig().working_width})")
    parser.add_argument("--monitor", default=None, metavar="SPEC",
                        help="runtime monitor: none, lhd, 'lhd+ch:tau=0.25', 'lhd+mcd:n=10,rho=0.9', "
                             "'lhd+ch+mcd:tau=0.125,n=30,rho=0.5', a registered monitor such as msp "
                             "(default: the deployed monitor, el.flight.pipeline.DEPLOYED_MONITOR, or the "
                             "--calibration card's monitor; model pipeline)")
    parser.add_argument("--calibration", type=Path, metavar="CALIB.json",
                        help="calibration card (uav-el calibrate): run the monitor at its calibrated threshold")
    parser.add_argument("--gate", type=Path, metavar="GATE.json",
                        help="frame gate (uav-el fit-gate; 'none': no gate; default: the system file's [monitor] "
                             "gate, else el.flight.pipeline.DEPLOYED_GATE on the shipped network): a frame "
                             "above its threshold takes the default action (out_of_domain); its score is in the "
                             "decision JSON")
    parser.add_argument("--weights", "--model", dest="weights", metavar="MODEL",
                        help="segmentation model: a .pt weights file with its card, an .onnx file, or a name "
                             "registered in the uav_el.models entry points (NAME or NAME:ARG); default: the system's "
                             "network ([model] of the system file; the shipped one without)")
    parser.add_argument("--budget", type=float, default=None, metavar="S",
                        help="time budget in seconds; past it, the default action (default: the system file's "
                             f"[targets] time_budget_s, else {DEFAULT_TIME_BUDGET_S})")
    parser.add_argument("--seed", type=int, default=0, help="seed of MC dropout (default: %(default)s)")
    parser.add_argument("--max-pixels", type=int, default=MAX_PIXELS, metavar="N",
                        help="largest frame accepted, in pixels, checked from the file's header before decoding "
                             "(default: %(default)s, 8K plus a quarter)")
    parser.add_argument("--threads", type=int, help="CPU threads for the CNN (default: torch's choice)")
    parser.add_argument("--all", action="store_true", dest="evaluate_all",
                        help="evaluation mode: run the monitor on every candidate (the decision is unchanged)")
