"""MPI helper of tests/integration/test_materials.py: the elastic + Voce blocks solved on any number of ranks.

    mpiexec -n N python mixed_materials.py OUT.npz

Rank 0 writes every node's position and displacement (gathered) and the largest p of the Voce body.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))  # the test module this script runs

from test_materials import _solve  # noqa: E402

if __name__ == "__main__":
    problem, _ = _solve("monolithic", "alart-curnier", "voce")
    n = problem.V.dofmap.index_map.size_local
    x = problem.V.tabulate_dof_coordinates()[:n]
    u = problem.u.x.array.reshape(-1, 3)[:n]
    maxima = problem.state.maxima_by_body()
    xs, us = MPI.COMM_WORLD.gather(x), MPI.COMM_WORLD.gather(u)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(sys.argv[1], x=np.concatenate(xs), u=np.concatenate(us), max_p=maxima["p"]["2"])
