"""The installed flow end to end (.ci/wheel-check): the wheel installed non-editable in a fresh environment inside
another git repository runs synth -> campaign -> uav-el verify (with a user's own requirement test) -> evidence,
identified by its version and file hash (no git commit), and the sdist's tests pass from the unpacked sdist.
Slow (builds, installs, runs a tiny campaign: minutes)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_the_wheel_decides_its_requirements_installed_inside_another_repository():
    script = ROOT / ".ci" / "wheel-check"
    if not script.is_file():
        pytest.skip("no .ci/wheel-check here")
    out = subprocess.run(["bash", str(script)], capture_output=True, text=True, timeout=3000,
                         env={**os.environ, "PYTHON": sys.executable})
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-4000:]
    assert "wheel check passed" in out.stdout and "with no git commit" in out.stdout
