"""Finite strain on 2 ranks: the serial answer (issue 41).

A rigid sphere pressed 10 % of the block's height into an elastoplastic block (kinematics "finite",
the contact in the current geometry; tests/mpi_scripts/finite_strain.py), monolithic and NNEQM1:
the sphere's force and the Cauchy stress and p at every Gauss point (compared by position) equal the
serial run's.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_nnqem import compat

SCRIPTS = Path(__file__).resolve().parents[1] / "mpi_scripts"
sys.path.insert(0, str(SCRIPTS))

from finite_strain import METHODS, solve  # noqa: E402


def _order(x):
    x = x.round(9)
    return np.lexsort((x[:, 2], x[:, 1], x[:, 0]))


@pytest.mark.mpi
def test_finite_strain_contact_on_two_ranks_matches_serial(tmp_path):
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "finite_strain.py"), str(out)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    for method in METHODS:
        s = solve(method, MPI.COMM_SELF)
        p = {key.split("/", 1)[1]: value for key, value in parallel.items() if key.startswith(f"{method}/")}
        i, j = _order(p["x"]), _order(s["x"])
        scale = np.abs(s["sigma"]).max()
        dsigma = np.abs(p["sigma"][i] - s["sigma"][j]).max() / scale
        dp = np.abs(p["p"][i] - s["p"][j]).max() / max(np.abs(s["p"]).max(), 1e-300)
        dF = np.linalg.norm(p["force"] - s["force"]) / np.linalg.norm(s["force"])
        print(f"\n  {method}, 2 ranks vs serial: {len(i)} Gauss points, Cauchy stress {dsigma:.1e}, p {dp:.1e}, "
              f"sphere force {dF:.1e} (tolerance 1e-8); iterations serial {s['iterations'].tolist()}, "
              f"2 ranks {p['iterations'].tolist()}")
        assert len(i) == len(j) and np.abs(p["x"][i] - s["x"][j]).max() < 1e-12
        assert s["p"].max() > 0.0  # the block yields
        assert dsigma < 1e-8 and dp < 1e-8 and dF < 1e-8
