"""Several interfaces, a rigid obstacle and NNEQM2 (plastic bodies, an elastic one, yield in the first
increment, both variants) on 2 ranks: the same answer as serially, to 1e-8.

Pairs are owned by the rank of their slave node, so their global order depends on the number of
ranks: results are compared pair by pair after sorting by (interface, slave position).
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

from contact_cases import solve_case  # noqa: E402


def _order(data):
    x = data["position"].round(9)
    return np.lexsort((x[:, 2], x[:, 1], x[:, 0], data["interface"]))


@pytest.mark.mpi
@pytest.mark.parametrize("case, method", [("three_blocks", "monolithic"), ("three_blocks", "nneqm1"),
                                          ("three_blocks", "nneqm2"), ("elastic_on_plastic", "nneqm2"),
                                          ("plastic_drag", "nneqm2"), ("plane_press", "nneqm2"),
                                          ("plane_press", "nneqm2-frozen"),
                                          ("sphere", "monolithic"),
                                          ("sphere", "nneqm1")])
def test_two_ranks_match_serial(case, method, tmp_path):
    serial = solve_case(case, method, MPI.COMM_SELF)
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "contact_cases.py"), case, method, str(out)]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=compat.mpi_environment())
    assert result.returncode == 0, f"{' '.join(cmd)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    parallel = dict(np.load(out))
    i, j = _order(parallel), _order(serial)
    df = np.abs(parallel["force"][i] - serial["force"][j]).max() / np.abs(serial["force"]).max()
    du = np.abs(parallel["u"][i] - serial["u"][j]).max() / np.abs(serial["u"]).max()
    print(f"\n  {case}/{method}: {len(i)} pairs; 2 ranks vs serial: pair forces {df:.1e}, slave displacements "
          f"{du:.1e} (tolerance 1e-8); iterations serial {serial['iterations'].tolist()}, 2 ranks "
          f"{parallel['iterations'].tolist()}")
    assert max(df, du) < 1e-8
