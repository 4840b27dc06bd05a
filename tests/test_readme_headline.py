"""The README's headline table is the release run's (`make release-evidence` runs this on the release run).

Marked `campaign`: it reads a campaign run (--uav-el-run). It judges only a release-sized run (the
release preset's images and perturbations); on any other run it is skipped.

A release run made on another machine reproduces the table within
``assurance.analysis.headline.REPRODUCIBILITY``: the header, every unsafe-landing count, rate and bound exactly, the
gains within one moved decision per perturbation (docs/results.md, "Reproducibility across machines"); or the
table of a release run recorded on another instruction set (docs/headline-runs/), within the same tolerance; on
an instruction set no table was recorded on, one of them within ``ACROSS_INSTRUCTION_SETS`` (the run says which).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from assurance.analysis.headline import (
    ACROSS_INSTRUCTION_SETS,
    REPRODUCIBILITY,
    headline_markdown,
    reference_blocks,
    reproduced,
)
from assurance.analysis.table import results_table
from assurance.campaign.presets import preset_config
from assurance.campaign.readouts import read_manifest
from assurance.cli.table import release_parameters

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.mark.campaign
def test_readme_headline_table_is_the_release_runs(campaign_run):
    cfg = read_manifest(campaign_run)["config"]
    release = preset_config("release")
    if cfg.get("images") != release.images or tuple(cfg.get("perturbations", ())) != release.perturbations:
        pytest.skip(f"{campaign_run} is not a release-sized run (the headline table is about the release run)")
    block = headline_markdown(campaign_run, results_table(campaign_run), **release_parameters())
    found = reproduced(block, reference_blocks(README), REPRODUCIBILITY)
    if found.across:  # said in the run's warnings summary, not only in its captured output
        warnings.warn(f"{campaign_run} ran on an instruction set with no recorded headline; it reproduces "
                      f"{found.match} only within {ACROSS_INSTRUCTION_SETS}", stacklevel=1)
    assert found.match is not None, (
        f"neither README.md's headline table nor a recorded run of another instruction set is {campaign_run}'s "
        f"within {REPRODUCIBILITY}:\n" + "\n".join(f"{name}: {line}" for name, lines in found.differences.items()
                                                   for line in lines)
        + f"\n(this machine's run: `uav-el table {campaign_run} --readme README.md` writes it)")
