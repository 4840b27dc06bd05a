"""``uav-el table``: the results table of a campaign run (CSV + Markdown, optionally beside the paper's)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from assurance.analysis.findings import findings, findings_markdown
from assurance.analysis.floor import floor_markdown, monitor_floor
from assurance.analysis.headline import (
    ACROSS_INSTRUCTION_SETS,
    REPRODUCIBILITY,
    HeadlineError,
    headline_markdown,
    instruction_set_of,
    reference_blocks,
    reproduced,
    write_block,
)
from assurance.analysis.reference import load_reference
from assurance.analysis.scores import auroc_markdown, auroc_table
from assurance.analysis.table import compare, compare_markdown, results_table, to_markdown, write_csv
from assurance.campaign import readouts
from assurance.campaign.integrity import verify_run
from assurance.campaign.readouts import read_manifest
from assurance.campaign.stages import monitor_costs, monitor_costs_markdown, stage_table, stages_markdown, wall_seconds
from assurance.errors import CommandError
from assurance.files import atomic_write_bytes
from assurance.requirements import load_registry

HELP = "print and write the results table of a campaign run (CSV and Markdown, paper's Table I layout)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="campaign run folder")
    p.add_argument("--out", help="folder for results.csv and results.md (default: the run folder)")
    p.add_argument("--compare", action="store_true",
                   help="also put the figures beside the published ones (Guerin et al., ICRA 2022) and ask "
                        "the paper's findings of both")
    p.add_argument("--no-intervals", action="store_true", help="print point values only")
    p.add_argument("--boot", type=int, default=2000, help="bootstrap resamples (default 2000)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--readme", metavar="README.md", help="also write the headline table of the deployed "
                                                         "configuration between the file's headline markers")
    g.add_argument("--check-readme", metavar="README.md", help="only check that the file's headline table is "
                                                               "the run's (exit 1 naming the difference)")


def run(args: argparse.Namespace) -> int:
    import sys

    if args.boot < 1:
        raise CommandError("--boot must be >= 1")
    check = verify_run(args.run).raise_if_damaged()  # exit 4 naming the shard and file
    planned = read_manifest(args.run).get("tasks")
    if isinstance(planned, int) and check.shards < planned:
        print(f"warning: {args.run}: {check.shards} of {planned} task(s) finished (an unfinished campaign: "
              "run the same `uav-el campaign` command to complete it)", file=sys.stderr)
    if check.legacy:
        print(f"warning: {args.run}: written before shard hashes; its readouts cannot be verified", file=sys.stderr)
    images = readouts.load_table(args.run, "images")  # each read once: the results, AUROC and floor tables
    candidates = readouts.load_table(args.run, "candidates")
    df = results_table(args.run, n_boot=args.boot, images=images, candidates=candidates)
    if args.check_readme:
        return check_readme(args.run, df, args.check_readme)
    faulted = int(df.drop_duplicates(["perturbation", "severity"])["faults"].sum()) if len(df) else 0
    if faulted:
        print(f"warning: {args.run}: {faulted} faulted task(s) are left out of the table (see the faults column "
              "and the run's log)", file=sys.stderr)
    out = Path(args.out or args.run)
    write_csv(df, out / "results.csv")
    md = to_markdown(df, intervals=not args.no_intervals)
    if args.compare:
        merged = compare(df)
        write_csv(merged, out / "comparison.csv")
        md += "\n### Beside the published results (Guerin et al., ICRA 2022)\n\n" + compare_markdown(merged)
        md += "\n### The paper's findings, asked of both tables\n\n" + findings_markdown(findings(df, load_reference()))
    md += "\n### Monitor scores: AUROC (unsafe candidates as positives, 95% bootstrap interval over images)\n\n"
    md += auroc_markdown(auroc_table(candidates, n_boot=min(args.boot, 1000)))
    md += ("\n### What no monitor can prevent\n\nA perfect monitor lands on a truly safe candidate where the frame "
           "has one and takes the default action elsewhere; where the default area is unsafe too, it lands unsafely. "
           "Those frames are the floor under every configuration's unsafe landings above "
           "(`assurance.analysis.floor`). Nor can a monitor add more safety than the lowest true hazard on offer "
           "(a candidate or the default area) allows: the last column is the G_RM of an oracle that lands there, "
           "above which no configuration's G_RM can lie:\n\n")
    md += floor_markdown(monitor_floor(images, candidates))
    md += "\n### Where the time went\n\n" + stages_markdown(stage_table(args.run), wall_seconds(args.run))
    md += "\nMonitoring time per candidate, by configuration:\n\n" + monitor_costs_markdown(monitor_costs(args.run))
    atomic_write_bytes(out / "results.md", md.encode())
    if not getattr(args, "quiet", 0):  # -q: the files and one line
        print(md)
    written = [out / "results.csv", out / "results.md"] + ([out / "comparison.csv"] if args.compare else [])
    if args.readme:
        written.append(write_readme(args.run, df, args.readme))
    print("written: " + ", ".join(map(str, written)))
    return 0


def _headline(run: str, df: Any) -> str:
    try:
        return headline_markdown(run, df, **release_parameters())
    except HeadlineError as exc:
        raise CommandError(str(exc)) from None


def write_readme(run: str, df: Any, readme: str) -> str:
    """Write the headline block into ``readme``; the file's name."""
    block = _headline(run, df)
    try:
        changed = write_block(readme, block)
    except (HeadlineError, OSError) as exc:
        raise CommandError(str(exc)) from None
    print(f"{readme}: headline table {'updated' if changed else 'already up to date'}")
    return readme


def check_readme(run: str, df: Any, readme: str) -> int:
    """0 when ``readme`` shows the run's headline table, exactly or within the tolerance of a run made on another
    machine of the same instruction set (``assurance.analysis.headline.REPRODUCIBILITY``: the figures that differ
    are printed), or a recorded run of another instruction set does (``docs/headline-runs/`` beside it), or, on an
    instruction set no table was recorded on, one of them does within ``ACROSS_INSTRUCTION_SETS``; else 1 with
    what differs and both versions printed."""
    import sys

    block = _headline(run, df)
    try:
        references = reference_blocks(readme)  # the README's first, then the recorded runs of other instruction sets
    except (HeadlineError, OSError) as exc:
        raise CommandError(str(exc)) from None
    shown = references[0][1]
    if shown == block:
        print(f"{readme}: the headline table matches {run}")
        return 0
    found = reproduced(block, references, REPRODUCIBILITY)
    versions = f"--- README\n{shown}--- run\n{block}"
    if found.across:
        isa, other = instruction_set_of(block), instruction_set_of(dict(references)[found.match])
        print(f"{readme}: {run} ran on instruction set {isa!r}, on which no headline table was recorded; it "
              f"reproduces {found.match} (recorded on {other!r}) within {ACROSS_INSTRUCTION_SETS.counts} decisions "
              f"per perturbation and {ACROSS_INSTRUCTION_SETS.total} in all (docs/results.md); record this machine's "
              f"with `uav-el table {run} --readme docs/headline-runs/{isa}.md` (create it first, beside the README, "
              f"holding the README's two markers):\n{versions}", end="")
        return 0
    if found.match == Path(readme).name:
        print(f"{readme}: the headline table matches {run} within the tolerance of another machine "
              f"({REPRODUCIBILITY.decisions} decision per perturbation; docs/results.md), not exactly:\n{versions}",
              end="")
        return 0
    if found.match is not None:
        print(f"{readme}: {run} reproduces {found.match}, the headline table recorded on another instruction set "
              f"({'exactly' if dict(references)[found.match] == block else 'within the tolerance'}; "
              f"docs/results.md), not the README's:\n{versions}", end="")
        return 0
    print(f"{readme}: the headline table differs from {run} (and so does each recorded run of another instruction "
          f"set); run `uav-el table {run} --readme {readme}`\n"
          + "".join(f"  {name}: {d}\n" for name, lines in found.differences.items() for d in lines)
          + versions, file=sys.stderr)
    return 1


def release_parameters() -> dict[str, Any]:
    """The registry parameters the headline is judged with (deployed monitor, calibration card)."""
    p = load_registry().parameters
    return {"deployed": p["deployed_monitor"], "calibration_card": p.get("calibration_card")}
