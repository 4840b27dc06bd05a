"""The README headline table: written between markers from a run, and checked against it."""

from __future__ import annotations

import pytest

from assurance.analysis.headline import BEGIN, END, HeadlineError, current_block, headline_markdown, write_block
from assurance.analysis.table import results_table
from assurance.campaign.presets import preset_config, resolve_monitors
from el.flight.pipeline import PipelineConfig
from el.monitors import DEMO_GRID


def test_release_and_demo_presets_evaluate_the_deployed_configuration_first():
    for name, images in (("release", 70), ("demo", None)):  # the demo: every scene of the data
        cfg = preset_config(name)
        assert cfg.monitors[0] == PipelineConfig().monitor_name
        assert set(DEMO_GRID) <= set(cfg.monitors) and len(set(cfg.monitors)) == len(cfg.monitors)
        assert cfg.images == images and len(cfg.perturbations) == 6
    assert resolve_monitors(["lhd", "demo-grid"]) == DEMO_GRID  # keywords expand, duplicates drop


def test_headline_block_round_trip_and_mismatch(tiny_campaign, tmp_path):
    run = tiny_campaign["run"]
    table = results_table(run, n_boot=50)
    block = headline_markdown(run, table, "lhd")
    assert block.count("\n| ") == 6 + 1  # header + one row per perturbation
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{BEGIN}\nold\n{END}\noutro\n")
    assert write_block(readme, block) and not write_block(readme, block)
    assert current_block(readme) == block
    text = readme.read_text()
    assert text.startswith("intro\n") and text.endswith("outro\n")
    readme.write_text(text.replace(" of 10", " of 11", 1))
    assert current_block(readme) != block
    with pytest.raises(HeadlineError, match="no configuration 'msp'"):
        headline_markdown(run, table, "msp")
    readme.write_text("no markers\n")
    with pytest.raises(HeadlineError, match="headline markers"):
        current_block(readme)
