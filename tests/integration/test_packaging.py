"""The wheel and the sdist build without warnings, carry the SPDX licence and install into a fresh
environment where the command solves a problem file (scripts/check-wheel; about a minute)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_wheel_and_sdist_install_and_run():
    run = subprocess.run(["bash", str(ROOT / "scripts" / "check-wheel")], capture_output=True, text=True,
                         timeout=900, env={**os.environ, "PYTHON": sys.executable})
    print("\n" + run.stdout + run.stderr[-3000:])
    assert run.returncode == 0 and "check-wheel: OK" in run.stdout
