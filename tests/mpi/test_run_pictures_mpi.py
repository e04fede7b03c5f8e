"""The run pictures of a run on 2 ranks: drawn once, by rank 0, from the folder (the fields are
read in a child process that must not join the MPI job)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from dolfinx_nnqem import compat
from dolfinx_nnqem.io.run_pictures import ENV_SWITCH, PICTURES

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.mpi
@pytest.mark.slow  # about 60 s on two shared cores (two ranks, VTK, the child reader)
def test_two_ranks_draw_every_picture(tmp_path):
    env = {k: v for k, v in compat.mpi_environment().items() if k != ENV_SWITCH}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, "-m", "dolfinx_nnqem", "run",
           str(ROOT / "demos" / "two_beams.toml"), "--increments", "2", "--out", str(tmp_path / "out")]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=ROOT)
    print("\n" + run.stdout + run.stderr[-2000:])
    assert run.returncode == 0
    assert "not drawn" not in run.stdout + run.stderr
    assert run.stdout.count("pictures: ") == 1  # rank 0 alone reports
    assert not (tmp_path / "out" / "pictures" / "error_estimates.png").exists()  # drawn with --estimate only
    for name in (name for name in PICTURES if name != "error_estimates.png"):
        assert (tmp_path / "out" / "pictures" / name).stat().st_size > 10_000, name
