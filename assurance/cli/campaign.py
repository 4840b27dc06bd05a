"""``uav-el campaign``: run (or resume) an evaluation campaign over perturbations x images x monitors."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from assurance.attest import AttestationError
from assurance.attest.keys import load_signing_key
from assurance.campaign.faults import config_fault_line
from assurance.campaign.perturbation_plan import domain_record, outside_lines, system_plan
from assurance.campaign.presets import MonitorSupportError, campaign_monitors, load_presets, preset_config
from assurance.campaign.run import Execution, campaign_network, describe, network_threads, run_campaign
from assurance.cli.arguments import model_option
from assurance.cli.system_options import assessed
from assurance.dataio.layouts import iter_samples
from assurance.dataio.poses import POLICIES
from assurance.errors import CommandError
from assurance.workers import bounded_jobs
from el.monitors import build_monitor
from el.monitors.calibration import check_card_monitor, load_calibration
from el.monitors.frame_gate import GateFile, load_frame_gate

HELP = "run or resume an evaluation campaign (perturbations x test images x monitor configurations)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", help="labelled test scenes, a folder of a known layout (uavid, semantic-drone, "
                                  "aeroscapes: detected); default: the system file's [data] test")
    p.add_argument("--out", required=True, help="run folder (created; re-running resumes it)")
    p.add_argument("--preset", default="demo", choices=sorted(load_presets()),
                   help="campaign preset (default: demo); the options below override its fields")
    p.add_argument("--perturbations", nargs="+", metavar="NAME",
                   help="perturbations to apply (default: the preset's; its `declared`: the system's [odd] "
                        "perturbations and [targets] required_perturbations, with none); one outside the declared "
                        "domain runs, said and marked in the run")
    p.add_argument("--severities", nargs="+", type=int, metavar="S", help="severities 1-5")
    p.add_argument("--monitors", nargs="+", metavar="SPEC", help="monitor configurations, e.g. lhd 'lhd+ch:tau=0.25'")
    p.add_argument("--calibration", nargs="+", metavar="CALIB.json",
                   help="calibration card(s) (uav-el calibrate): also evaluate each calibrated monitor")
    p.add_argument("--images", type=int, help="use the first N scenes of --data (default: every scene, except the "
                                              "release preset's 70; the command says when scenes are left out)")
    p.add_argument("--gate", metavar="GATE.json",
                   help="frame gate (uav-el fit-gate; 'none': no gate; default: the system file's [monitor] gate, "
                        "else el.flight.pipeline.DEPLOYED_GATE on the shipped network): every image row "
                        "records its score and threshold; a frame above it is decided as the default action")
    model_option(p)
    p.add_argument("--seed", type=int, help="campaign seed (perturbations, MC dropout)")
    p.add_argument("--poses", choices=POLICIES, default=None,
                   help="pose of each frame (default: the system file's [camera] poses, else nominal): nominal (the "
                        "configured pose for all), sidecar (a frame's line of seqNN/poses.csv, else a synthetic "
                        "scene's meta, else nominal), required (as sidecar, but a frame without its own pose is a "
                        "recorded fault)")
    p.add_argument("--jobs", type=int, default=1,
                   help="parallel workers (default 1; more than the CPU cores are clamped to them, with a warning)")
    p.add_argument("--backend", choices=("loky", "dask"), default="loky", help="parallel backend (default loky)")
    p.add_argument("--scheduler", help="address of a running dask.distributed scheduler (with --backend dask)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--signing-key", metavar="PEM", help="Ed25519 key that signs the run (default: $UAV_EL_SIGNING_KEY, "
                   "else your key file, created on first use; see uav-el keys)")


def run(args: argparse.Namespace) -> int:
    if args.jobs < 1:
        raise CommandError("--jobs must be >= 1")
    if args.scheduler and args.backend != "dask":
        raise CommandError("--scheduler needs --backend dask")
    if not args.scheduler:  # local workers: clamped to the cores, one warning line says so
        args.jobs = bounded_jobs(args.jobs, warn=lambda m: print(f"uav-el campaign: warning: {m}", file=sys.stderr))
    system = assessed(args)  # the system under assessment, with --model and --gate: what the campaign runs
    data = system.data("test", args.data)
    deployed, cards = _deployed(args, system)
    monitors = _monitors(args, system, deployed, cards)
    gate = None
    if system.gate is not None:  # a bad gate file: one line, exit 2, before any task
        gate = load_frame_gate(system.gate)
        cards.append(gate)  # checked against the campaign's network with the cards
    plan = system_plan(system)  # the system's perturbations: what the preset's `declared` stands for
    config = preset_config(
        args.preset, deployed=deployed, plan=plan, core=system.core,
        perturbations=tuple(args.perturbations) if args.perturbations else None,
        severities=tuple(args.severities) if args.severities else None,
        monitors=monitors,
        images=args.images, weights=system.model, seed=args.seed,
        poses=args.poses or system.poses, odd=system.odd, gate=GateFile.of(gate),
    )
    for line in outside_lines(domain_record(config.perturbations, config.scenarios(), config.odd), plan,
                              system.label, own_required=system.file.required_perturbations is not None):
        print(f"uav-el campaign: {line}", file=sys.stderr)
    _say_scenes(data, config.images, args)
    try:
        key = load_signing_key(args.signing_key, outside=args.out)
    except AttestationError as exc:
        raise CommandError(str(exc)) from None
    execution = Execution(jobs=args.jobs, backend=args.backend, scheduler=args.scheduler, progress=not args.quiet)
    summary = run_campaign(data, args.out, config, execution=execution, records=cards, system=system.file,
                           signing_key=key)
    head, *problems = describe(summary).splitlines()
    print(head)
    for line in problems if not summary.get("config_faults") else ():  # warnings, shown under -q too
        print(line, file=sys.stderr)  # (tasks that faulted for a configuration reason: the one error line below)
    print(f"signed: {summary['attestation']} (key {key.keyid[:16]}, {key.source})")
    print(f"readouts in {args.out}; results table: uav-el table {args.out}")
    if summary.get("config_faults"):  # every such task measured nothing: fail loud (exit 2)
        raise CommandError(config_fault_line(summary["config_faults"]))
    return 1 if summary["missing"] else 0


def _deployed(args: argparse.Namespace, system: Any) -> tuple[str | None, list[Any]]:
    """The system's deployed configuration as it flies (its spec at its card's threshold, or a card's own spec)
    and the calibration cards the campaign evaluates (``--calibration``, else the system file's), each checked
    against its monitor. Exit 2 for a deployed spec off its card's threshold."""
    spec, card = system.deployed()  # a deployed spec off its card's threshold: exit 2
    deployed = load_calibration(card).spec if card is not None else spec
    card_paths = args.calibration or ([str(system.calibration)] if system.calibration is not None else [])
    cards = [load_calibration(c) for c in card_paths]
    for c in cards:
        check_card_monitor(c, build_monitor(c.spec, labels=system.labels))
    return (deployed or None), cards


def _monitors(args: argparse.Namespace, system: Any, deployed: str | None, cards: list[Any]) -> tuple[str, ...]:
    """The configurations the campaign evaluates, each checked once against the system's network before any task
    (``assurance.campaign.presets.campaign_monitors``): one the preset brought in that the network cannot run is
    left out with a printed line; the deployed one, or one asked for (``--monitors``, a card), refuses the
    campaign (exit 2, one line naming it and the system file)."""
    # the campaign's own network (assurance.campaign.run keeps it for its checks and a sequential run's tasks); a
    # model that cannot load: exit 2
    model = campaign_network(system.model, network_threads(args.jobs), system.core.working_width)
    try:
        choice = campaign_monitors(args.preset, deployed=deployed, given=args.monitors,
                                   extra=[c.spec for c in cards], model=model, where=system.label)
    except MonitorSupportError as exc:
        raise CommandError(str(exc)) from None
    for name, why in choice.left_out:
        print(f"uav-el campaign: left out {name!r}: the network of {system.label} cannot run it ({why})",
              file=sys.stderr)
    if not choice.monitors:
        raise CommandError(f"no monitor configuration of preset {args.preset!r} can run on the network of "
                           f"{system.label}: give --monitors")
    return choice.monitors


def _say_scenes(data: Any, images: int | None, args: argparse.Namespace) -> None:
    """One line when the campaign evaluates fewer scenes than the data holds: how many, of how many, and why
    (``--images``, or the preset's stated size)."""
    if images is None:
        return
    total = sum(1 for _ in iter_samples(data, require_labels=True))
    if total > images:
        why = "--images" if args.images is not None else f"the {args.preset} preset's size"
        print(f"uav-el campaign: evaluating the first {images} of the {total} scenes of {data} ({why}); "
              "the others are not evaluated", file=sys.stderr)
