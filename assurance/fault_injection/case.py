"""One fault-injection case and the scratch workspace it is injected into (``assurance.fault_injection.table``).

The workspace (``build_workspace`` there): ``WS/data`` (two 320x180 synthetic test scenes), ``WS/tiny.pt`` (a
tiny CNN's weights and card) and ``WS/run`` (a finished 2-image campaign on them). The helpers below name
its parts, so the modules of cases agree on them.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from assurance.campaign import readouts
from el.base.hashing import sha256_file

CliMain = Callable[[list[str]], int]  # ``assurance.cli.main``: argv -> exit code


@dataclass(frozen=True)
class Case:
    """One fault: ``make(ws)`` injects it (into copies under the workspace) and returns the argv to run."""

    id: str
    injected: str
    make: Callable[[Path], list[str]]
    expected: int
    expect_text: str = ""  # words the output must hold (e.g. the decision's reason)
    pick: str = ""  # the output line holding this is the outcome (default: first stderr line)
    check: Callable[[Path], str | None] | None = None  # after the command: what is wrong with what it left, or None


_CLI: list[CliMain] = []  # the command line the cases run through (set by ``fault_injection.run_case``)


def write_small_frame_system(folder: Path) -> Path:
    """``folder/uav-el.toml``: the embedded default but for a declared domain that admits small frames (64-7680 x
    36-4320 px; the default declares only its camera's 4K frames), for workspaces of tiny test scenes."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "uav-el.toml"
    path.write_text('format = "uav-el-system/1"\n\n[odd]\nimage_width = [64, 7680]\nimage_height = [36, 4320]\n',
                    encoding="utf-8")
    return path


def use_cli(main: CliMain) -> None:
    """Run the cases' preparation steps (``prepare``) through ``main`` (``assurance.cli.main``)."""
    _CLI[:] = [main]


def run_cli(main: CliMain, argv: Sequence[object]) -> tuple[int, str, str]:
    """``uav-el ARGV`` in-process through ``main``: (exit code, stdout, stderr)."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse's own refusals
            code = int(exc.code or 0)
    return code, out.getvalue(), err.getvalue()


def prepare(argv: list[object]) -> int:
    """``uav-el ARGV`` in-process, its output dropped: a case's preparation (a campaign, a verify), not its
    outcome. The command line must have been given (``use_cli``)."""
    if not _CLI:
        raise RuntimeError("fault-injection case preparation: no command line given (use_cli)")
    return run_cli(_CLI[0], argv)[0]


def campaign_argv(ws: Path, out: Path, *extra: str, data: Path | None = None, weights: Path | None = None
                  ) -> list[str]:
    """``uav-el campaign`` on the workspace's data (or ``data``) and tiny weights (or ``weights``), into ``out``."""
    return ["campaign", "--data", str(data or ws / "data"), "--out", str(out), "--weights",
            str(weights or ws / "tiny.pt"),
            "--perturbations", "none", "--monitors", "lhd", "--images", "2", *extra]


def first_image(ws: Path) -> Path:
    """The workspace's first test image."""
    return sorted((ws / "data").glob("*/Images/*.png"))[0]


def copy_run(ws: Path, name: str) -> tuple[Path, list[Path]]:
    """A copy of the workspace's finished run as ``WS/name``, and its shard folders."""
    run = ws / name
    shutil.copytree(ws / "run", run)
    return run, sorted(p for p in (run / "shards").iterdir() if p.is_dir())


def reseal_shard(run: Path, name: str) -> None:
    """Re-hash an edited shard in its own SHA256SUMS and the run's index, as a forger (or a test that needs odd
    readouts that still verify) would: only a signed statement over the files still tells the edit."""
    folder = Path(run) / readouts.SHARDS / name
    sums = {f: sha256_file(folder / f) for f in readouts.shard_files()}
    (folder / readouts.SUMS).write_text("".join(f"{h}  {f}\n" for f, h in sums.items()), encoding="utf-8")
    readouts.record_shards(run, {name: sums})


def save_tiny_weights(path: Path, *, nan: bool = False) -> Path:
    """A tiny randomly-initialised CNN (seed 0) and its card; ``nan``: every parameter NaN."""
    import torch

    from assurance.fitting.network.weights_io import save_weights  # deferred: imports torch (the train extra)
    from el.segmentation.architectures import build_model  # deferred: imports torch (the train extra)
    from el.segmentation.model import ArchConfig  # deferred: imports torch (the train extra)

    torch.manual_seed(0)
    model = build_model(ArchConfig(widths=(8, 8, 8), decoder_channels=8))
    if nan:
        with torch.no_grad():
            for p in model.parameters():
                p.fill_(float("nan"))
    save_weights(model, path)
    return path
