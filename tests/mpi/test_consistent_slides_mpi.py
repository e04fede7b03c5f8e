"""The consistent linearisation of the current contact geometry on 2 ranks: the serial answer, in the
serial iterations (issues 41 and 43).

The frictional block slid 1.6 master facets over another (tests/mpi_scripts/large_sliding.py):

* ``blocks``, node-to-surface pairs: most pairs have a master node owned by the other rank, so the
  geometric blocks K (slave node × master nodes) are assembled across ranks and the closest points
  are found on the gathered, moved surfaces;
* ``mortar``, dual mortar pairs: every rank integrates the gathered, moved surfaces and differentiates
  the couples, keeps the rows of the pairs whose slave node it owns, and the blocks K (each pair's
  nodes × the nodes its geometry depends on, slave neighbours and master nodes on either rank) are
  assembled across ranks.

The monolithic solver (consistent) must give the serial pair forces and the serial Newton iterations,
and take far fewer than NNEQM1, which keeps the geometry frozen within a solve.
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

from large_sliding import solve  # noqa: E402


def _order(position):
    x = position.round(9)
    return np.lexsort((x[:, 2], x[:, 1], x[:, 0]))


@pytest.mark.mpi
@pytest.mark.parametrize(("case", "fraction"), [("blocks", 0.6), ("mortar", 0.5)],
                         ids=["node-to-surface", "mortar"])
def test_consistent_slide_on_two_ranks_matches_serial(tmp_path, case, fraction):
    """``fraction``: the largest share of NNEQM1's Newton iterations (frozen geometry) the consistent
    solver may take on 2 ranks."""
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "large_sliding.py"), str(out), case]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    s = solve(case, "monolithic", MPI.COMM_SELF)
    p = {key.rsplit("/", 1)[1]: value for key, value in parallel.items() if key.startswith(f"{case}/monolithic/")}
    nneqm1 = parallel[f"{case}/nneqm1/iterations"]
    i, j = _order(p["position"]), _order(s["position"])
    df = np.abs(p["force"][i] - s["force"][j]).max() / np.abs(s["force"]).max()
    print(f"\n  {case}, monolithic, 2 ranks vs serial: {len(i)} pairs (per rank {p['pairs_per_rank'].tolist()}), "
          f"{int(p['foreign_masters'])} with a master node on the other rank; pair forces {df:.1e}; iterations "
          f"serial {s['iterations'].tolist()} ({s['iterations'].sum()}), 2 ranks {p['iterations'].tolist()} "
          f"({p['iterations'].sum()}); NNEQM1 on 2 ranks (frozen geometry) {nneqm1.tolist()} ({nneqm1.sum()})")
    assert len(i) == len(j) and np.abs(p["position"][i] - s["position"][j]).max() < 1e-9
    assert np.count_nonzero(p["pairs_per_rank"]) == 2 and p["foreign_masters"] > 0
    assert df < 1e-8
    assert p["iterations"].tolist() == s["iterations"].tolist()
    assert p["iterations"].sum() < fraction * nneqm1.sum()  # the consistent linearisation on 2 ranks



@pytest.mark.mpi
@pytest.mark.parametrize("case", ["blocks", "mortar"], ids=["node-to-surface", "mortar"])
def test_the_iterative_solver_on_two_ranks_keeps_the_frozen_geometry(tmp_path, case):
    """On several ranks the iterative linear solver keeps the geometry frozen within a solve (the
    consistent terms are taken on one rank only: ``docs/theory.md``): it ends on the serial direct
    solver's pair forces, in the frozen geometry's many Newton iterations."""
    out = tmp_path / "out.npz"
    cmd = [*compat.mpiexec(), "-n", "2", sys.executable, str(SCRIPTS / "large_sliding.py"), str(out), f"{case}/iterative"]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=compat.mpi_environment())
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    parallel = dict(np.load(out))
    s = solve(case, "monolithic", MPI.COMM_SELF)
    p = {key.rsplit("/", 1)[1]: value for key, value in parallel.items() if key.startswith(f"{case}/iterative/")}
    i, j = _order(p["position"]), _order(s["position"])
    df = np.abs(p["force"][i] - s["force"][j]).max() / np.abs(s["force"]).max()
    print(f"\n  {case}, iterative linear solver on 2 ranks vs the direct one serial: pair forces {df:.1e}; "
          f"Newton iterations {p['iterations'].sum()} against {s['iterations'].sum()} (consistent, serial)")
    assert len(i) == len(j) and np.abs(p["position"][i] - s["position"][j]).max() < 1e-9
    assert df < 1e-8
    assert p["iterations"].sum() > 2 * s["iterations"].sum()  # the frozen geometry's repeated solves
