"""Error estimates on 2 ranks: the same quantities, estimates and indicator as serially.

The enriched solve is distributed like the run (degree 2 on the same partition; the uniformly
refined mesh keeps each child on its parent's rank, tags carried across ranks). Degree 2 on the
same mesh gives the serial estimates to round-off; the uniformly refined mesh is not the same
mesh on 2 ranks (Plaza's choice of the inner octahedron's diagonal follows the local vertex
numbering), and its estimates agree to a few per cent of themselves.
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

from estimates import solve_case  # noqa: E402


@pytest.mark.mpi
@pytest.mark.parametrize("case", ["sphere", "refine"])
def test_two_ranks_give_the_serial_estimates(case, tmp_path):
    serial = solve_case(case, MPI.COMM_SELF)
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "estimates.py"), case, str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    parallel = dict(np.load(out))
    assert parallel["names"].tolist() == serial["names"].tolist()
    assert parallel["dofs"].tolist() == serial["dofs"].tolist()
    scale = np.abs(serial["value"]).max(axis=1, keepdims=True) + 1e-300
    dv = np.abs(parallel["value"] - serial["value"]) / scale
    de = np.abs(parallel["enriched"] - serial["enriched"]) / scale
    # an estimate below 1e-6 of its quantity is round-off of the two solves (rtol 1e-10): there the
    # difference is measured against that floor (Debian's stack: 4e-13 of the quantity, 1.7e-4 of
    # an estimate of 2e-9 of it)
    dest = np.abs(parallel["estimate"] - serial["estimate"]) / np.maximum(serial["estimate"], 1e-6 * scale[:, 0])
    deta = abs(parallel["eta"][0] - serial["eta"][0]) / serial["eta"][0]
    print(f"\n  {case}: {serial['names'].tolist()}, dofs {serial['dofs'].tolist()}; 2 ranks vs serial: values "
          f"{dv.max():.1e}, enriched {de.max():.1e}, estimates {dest.max():.1e}, η {deta:.1e}")
    assert max(dv.max(), deta) < 1e-8
    if case == "sphere":  # degree 2 on the same mesh: the same enriched problem
        assert de.max() < 1e-8 and dest.max() < 1e-6
    else:  # Plaza splits each refined tetrahedron's inner octahedron along a diagonal chosen by the
        # local vertex numbering: the refined meshes differ between partitions (same sizes); the
        # estimates agree to some per cent of themselves (measured: enriched values 0.8 % and estimates
        # 1.5 % with DOLFINx 0.11, 2.6 % and 10 % with Debian's 0.9), far below what they estimate
        assert de.max() < 5e-2 and dest.max() < 0.2
