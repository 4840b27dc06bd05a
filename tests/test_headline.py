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


def test_a_run_reproduces_the_readme_or_a_recorded_run_of_another_instruction_set(tmp_path):
    """The README's table, then each table of docs/headline-runs/ beside it: the first one the run reproduces."""
    from assurance.analysis.headline import ALTERNATES, reference_blocks, reproduced

    head = "| perturbation | a | b | c | d | e | f | g |\n|---|---|---|---|---|---|---|---|\n"
    row = ("| fog | {} of 70 | 28 of 70 | 0.400 (0.505) | +0.272 | +0.052 [-0.007, +0.112] | +0.325 [+0.232, +0.437] "
           "| 0.451 / 0.207 |\n")
    readme, other = head + row.format(32), head + row.format(31)
    (tmp_path / "README.md").write_text(f"{BEGIN}\n{readme}{END}\n")
    refs = reference_blocks(tmp_path / "README.md")
    assert [name for name, _ in refs] == ["README.md"]
    assert reproduced(readme, refs) == ("README.md", {})
    match, differences = reproduced(other, refs)
    assert match is None and "must be equal" in differences["README.md"][0]
    (tmp_path / ALTERNATES).mkdir(parents=True)
    (tmp_path / ALTERNATES / "avx2.md").write_text(f"# the AVX2 run\n\n{BEGIN}\n{other}{END}\n")
    refs = reference_blocks(tmp_path / "README.md")
    match, differences = reproduced(other, refs)
    assert match == "docs/headline-runs/avx2.md" and list(differences) == ["README.md"]
    assert reproduced(head + row.format(30), refs)[0] is None
