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
    assert reproduced(readme, refs).match == "README.md"
    found = reproduced(other, refs)
    assert found.match is None and "must be equal" in found.differences["README.md"][0]
    (tmp_path / ALTERNATES).mkdir(parents=True)
    (tmp_path / ALTERNATES / "avx2.md").write_text(f"# the AVX2 run\n\n{BEGIN}\n{other}{END}\n")
    refs = reference_blocks(tmp_path / "README.md")
    found = reproduced(other, refs)
    assert found.match == "docs/headline-runs/avx2.md" and list(found.differences) == ["README.md"]
    assert not found.across
    assert reproduced(head + row.format(30), refs).match is None


HEADER = ("Deployed configuration `m`; model sha256 `0d3dab88c2b0`; 70 test scenes per perturbation (severity 3); "
          "run on a CPU of instruction set `{}`.\n\n| perturbation | a | b | c | d | e | f | g |\n"
          "|---|---|---|---|---|---|---|---|\n")
FOG = "| fog | {} of 70 | {} of 70 | {} | +0.272 | +0.052 [-0.007, +0.112] | +0.325 [+0.232, +0.437] | {} |\n"


def test_on_an_instruction_set_with_no_recorded_table_the_counts_may_differ_by_a_few_decisions():
    """A run on AVX-512 against a README recorded on AVX2 (and nothing recorded for AVX-512): the counts within 5 of
    70; an altered table, or a run of the README's own instruction set, is held to the exact counts."""
    from assurance.analysis.headline import ACROSS_INSTRUCTION_SETS, instruction_set_of, reproduced

    readme = HEADER.format("avx2") + FOG.format(31, 28, "0.400 (0.505)", "0.451 / 0.207")
    refs = [("README.md", readme)]
    assert instruction_set_of(readme) == "avx2" and instruction_set_of(FOG) is None
    moved = FOG.format(32, 31, "0.443 (0.548)", "0.429 / 0.209")  # the two machines measured (docs/results.md)
    found = reproduced(HEADER.format("avx512") + moved, refs)
    assert found.match == "README.md" and found.across
    assert reproduced(HEADER.format("avx2") + moved, refs).match is None  # its own instruction set: exact
    far = FOG.format(31, 22, "0.314 (0.414)", "0.451 / 0.207")  # 6 fewer unsafe landings than recorded
    found = reproduced(HEADER.format("avx512") + far, refs)
    assert found.match is None
    assert found.differences["README.md (another instruction set, avx2)"] == [
        f"fog: column 3 28 of 70 against 22 of 70 (within {ACROSS_INSTRUCTION_SETS.counts} of 70)",
        f"fog: column 4 0.400 (0.505) against 0.314 (0.414) (within {ACROSS_INSTRUCTION_SETS.counts} of 70)"]
    recorded = [*refs, ("docs/headline-runs/avx512.md", HEADER.format("avx512") + FOG.format(31, 28, "0.400 (0.505)",
                                                                                               "0.451 / 0.207"))]
    assert reproduced(HEADER.format("avx512") + moved, recorded).match is None  # recorded there: exact
    rate = FOG.format(31, 28, "0.443 (0.505)", "0.451 / 0.207")  # the rate altered, not the count
    assert reproduced(HEADER.format("avx512") + rate, refs).match is None


def test_the_run_manifest_names_its_instruction_set(tmp_path, monkeypatch):
    import platform

    from assurance.campaign.manifest import instruction_set

    info = tmp_path / "cpuinfo"
    monkeypatch.setattr(platform, "machine", lambda: "x86_64")
    for flags, isa in (("fpu sse2 avx avx2 fma", "avx2"), ("sse2 avx2 avx512f avx512bw", "avx512"), ("sse2", "x86-64")):
        info.write_text(f"processor\t: 0\nflags\t\t: {flags}\n")
        assert instruction_set(info) == isa
    assert instruction_set(tmp_path / "absent") == "x86-64"
    for name in ("aarch64", "arm64"):
        monkeypatch.setattr(platform, "machine", lambda name=name: name)
        assert instruction_set(info) == "aarch64"


def test_across_instruction_sets_a_table_made_to_look_safer_fails_on_its_total():
    """Each deployed count 4 lower (within 5 of a cell) is 24 fewer unsafe landings of 420: beyond the total's 8."""
    from assurance.analysis.headline import reproduced

    counts = {"none": (9, 6), "brightness": (25, 21), "fog": (31, 25), "motion_blur": (27, 19),
              "shifted_pixels": (9, 7), "pixel_trap": (5, 8)}

    def table(isa, shift=0, moved=()):
        rows = "".join(f"| {p} | {cm} of 70 | {dep + shift + (p in moved)} of 70 | r | +0.1 | +0.1 [+0.0, +0.2] "
                       f"| +0.1 [+0.0, +0.2] | 0.2 / 0.1 |\n" for p, (cm, dep) in counts.items())
        return HEADER.format(isa) + rows

    refs = [("README.md", table("avx2"))]
    assert reproduced(table("avx512", moved=("fog", "shifted_pixels")), refs).across  # two decisions moved
    found = reproduced(table("avx512", shift=-4), refs)
    assert found.match is None
    assert "column 3: 86 against 62 unsafe landings over the perturbations (within 8)" in \
        found.differences["README.md (another instruction set, avx2)"]
    assert reproduced(table("av\\x512", shift=0), refs).across  # a name the pattern would read as an escape
    edited = table("avx2").replace("| fog | 31 of 70 | 25 of 70 | r |", "| fog | 31 of 70 | 20 of 70 | 0.357 (0.462) |")
    from assurance.analysis.headline import inconsistencies

    assert inconsistencies(edited) == ["fog: rate 0.357 is not 20 of 70"] and inconsistencies(table("avx2")) == []
    found = reproduced(table("avx512"), [("README.md", edited)])
    assert found.match is None and found.differences["README.md (another instruction set, avx2)"] == [
        "fog: rate 0.357 is not 20 of 70"]


MEASURED_HEADER = ("Deployed configuration `verifier:fuse=learned,walk=score,threshold=0.810833523275059`, calibration "
                   "card `calibration.json` (sha256 `51516bde5ba4`); model sha256 `0d3dab88c2b0`; 70 test scenes per "
                   "perturbation (severity 3); run on a CPU of instruction set `{}`.\n\n"
                   "| perturbation | unsafe landings, CM alone | unsafe landings, deployed | "
                   "rate (one-sided 95% bound) | G_CM | G_RM [95%] | G* [95%] | recall / FP rate |\n"
                   "|---|---|---|---|---|---|---|---|\n")
MEASURED_ROWS = {  # per perturbation: (CM alone, deployed, rate, G_CM, G_RM, G*, recall / FP) on AVX2, then AVX-512
    "none": [("9", "6", "0.086 (0.162)", "+0.569", "-0.015 [-0.066, +0.045]", "+0.554 [+0.454, +0.642]",
              "0.197 / 0.026")] * 2,
    "brightness": [("25", "17", "0.243 (0.342)", g, "+0.077 [+0.017, +0.152]", "+0.378 [+0.285, +0.473]",
                    "0.128 / 0.006") for g in ("+0.302", "+0.301")],
    "fog": [("31", "24", "0.343 (0.447)", "+0.272", "+0.104 [+0.053, +0.168]", "+0.376 [+0.280, +0.487]",
             "0.444 / 0.055"),
            ("32", "26", "0.371 (0.476)", "+0.263", "+0.084 [+0.040, +0.155]", "+0.347 [+0.251, +0.458]",
             "0.365 / 0.054")],
    "motion_blur": [("27", "16", "0.229 (0.326)", "+0.286", "+0.132 [+0.059, +0.215]", "+0.418 [+0.307, +0.515]",
                     "0.507 / 0.139")] * 2,
    "shifted_pixels": [("9", "5", "0.071 (0.144)", "+0.561", "-0.001 [-0.054, +0.066]", "+0.560 [+0.460, +0.645]",
                        "0.559 / 0.153"),
                       ("9", "6", "0.086 (0.162)", "+0.558", "+0.011 [-0.037, +0.071]", "+0.569 [+0.465, +0.659]",
                        "0.579 / 0.142")],
    "pixel_trap": [("5", "5", "0.071 (0.144)", "+0.614", "-0.060 [-0.100, -0.021]", "+0.554 [+0.461, +0.637]",
                    "0.170 / 0.047"),
                   ("7", "7", "0.100 (0.180)", "+0.598", "-0.056 [-0.106, -0.008]", "+0.542 [+0.443, +0.629]",
                    "0.201 / 0.044")],
}


def measured_table(which: int) -> str:
    """The headline of the fused verifier at 0.811 as measured on AVX2 (0) and AVX-512 (1) (docs/results.md)."""
    rows = "".join(f"| {p} | {r[0]} of 70 | {r[1]} of 70 | {' | '.join(r[2:])} |\n"
                   for p, pair in MEASURED_ROWS.items() for r in [pair[which]])
    return MEASURED_HEADER.format(("avx2", "avx512")[which]) + rows


MEASURED_AVX2, MEASURED_AVX512 = measured_table(0), measured_table(1)


def test_across_instruction_sets_the_measured_pair_reproduces_each_other():
    """The release runs of one configuration (the fused verifier at 0.811) on AVX2 and AVX-512 (docs/results.md):
    counts within 2 of 70, sums within 5, fog's recall 0.079 apart; each passes the looser check against the other."""
    from assurance.analysis.headline import reproduced

    for run, recorded in ((MEASURED_AVX512, MEASURED_AVX2), (MEASURED_AVX2, MEASURED_AVX512)):
        found = reproduced(run, [("README.md", recorded)])
        assert found.match == "README.md" and found.across
    assert reproduced(MEASURED_AVX512.replace("| 26 of 70 | 0.371 (0.476) |", "| 18 of 70 | 0.257 (0.354) |"),
                      [("README.md", MEASURED_AVX2)]).match is None  # 8 fewer under fog: beyond a cell's 5
