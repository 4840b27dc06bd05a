"""The report's monitor-benchmark section: re-derived from the benchmark's CSV tables (the folder's own Markdown and
picture are never shown), listed in the table of contents, never moving the gate; a malformed folder is refused
before any work, naming the file."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from assurance import cli
from assurance.analysis.benchmark import write_benchmark
from assurance.evidence import generate
from assurance.evidence.benchmark_section import BenchmarkFolderError, read_benchmark


def _bench_folder(root: Path) -> Path:
    """A benchmark folder as ``uav-el benchmark`` writes it: 3 monitors, 4 perturbations, 2 criteria."""
    rng = np.random.default_rng(0)
    perts, monitors = ["none", "blur", "noise", "shift"], ["lhd", "msp", "odin"]
    rows = [{"monitor": m, "criterion": c, "threshold": 0.5, "note": "", "perturbation": p, "auroc": a,
             "images": 10, "miss_rate": 0.1, "fp_rate": 0.2, "unsafe_landings": 1.0, "g_star": 0.7}
            for c in ("f1", "g-star") for m, base in zip(monitors, (0.9, 0.7, 0.5), strict=True)
            for p, a in zip(perts, base + rng.normal(0, 0.01, 4), strict=True)]
    table = pd.DataFrame(rows)
    blocks = table[table["criterion"] == "f1"].pivot(index="perturbation", columns="monitor", values="auroc")
    out = root / "bench"
    write_benchmark(out, table, blocks, blocks="perturbation", measure="auroc", deployed="lhd", recall=0.95)
    (out / "benchmark.md").write_text("<script>alert('supplied markdown')</script>")
    return out


def test_the_section_is_recomputed_from_the_tables_and_listed(tiny_campaign, tmp_path):
    folder = _bench_folder(tmp_path)
    ctx = read_benchmark(folder)
    assert [r["monitor"] for r in ctx["auroc"]] == ["lhd", "msp", "odin"]  # best mean AUROC first
    assert ctx["ranking"]["ranks"][0]["monitor"] == "lhd" and ctx["diagram"].startswith("data:image/png;base64,")
    assert {c["criterion"] for c in ctx["criteria"]} == {"f1", "g-star"}
    html = generate(tiny_campaign["run"], tmp_path / "rep", pdf=False, n_boot=50, benchmark=folder).html.read_text()
    assert 'id="benchmark"' in html and 'href="#benchmark"' in html
    assert hashlib.sha256((folder / "blocks.csv").read_bytes()).hexdigest() in html
    assert "supplied markdown" not in html and "does not move the gate" in html


def test_a_report_without_benchmark_has_no_section(tiny_campaign, tmp_path):
    html = generate(tiny_campaign["run"], tmp_path / "rep", pdf=False, n_boot=50).html.read_text()
    assert 'id="benchmark"' not in html


@pytest.mark.parametrize("damage, says", [
    (lambda f: (f / "blocks.csv").unlink(), "blocks.csv"),
    (lambda f: (f / "benchmark.csv").write_text("monitor,auroc\nlhd,0.9\n"), "missing column"),
    (lambda f: (f / "blocks.csv").write_text("perturbation,lhd\nnone,__import__\n"), "not a number"),
])
def test_a_malformed_folder_is_refused_naming_the_file(tmp_path, damage, says):
    folder = _bench_folder(tmp_path)
    damage(folder)
    with pytest.raises(BenchmarkFolderError, match=says):
        read_benchmark(folder)


def test_the_command_refuses_a_bad_folder_with_exit_2(tiny_campaign, tmp_path, capsys):
    code = cli.main(["evidence", "--run", str(tiny_campaign["run"]), "--out", str(tmp_path / "rep"), "--no-pdf",
                     "--benchmark", str(tmp_path / "nowhere")])
    assert code == 2 and "not a folder" in capsys.readouterr().err
