"""MPI helper of tests/integration/test_sphere_press.py: the combined-hardening press and lift, monolithic.

    mpiexec -n N python sphere_press.py OUT.npz

Rank 0 writes the force and the depth after each increment and the number of cells each rank owns.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))  # the test module this script runs

from test_sphere_press import press  # noqa: E402

if __name__ == "__main__":
    forces, depths = press("monolithic", comm=MPI.COMM_WORLD)
    from dolfinx_nnqem.cases import sphere_press as case

    problem = case.sphere_press_problem(1.0, "combined", 1, comm=MPI.COMM_WORLD)
    cells = MPI.COMM_WORLD.gather(problem.mesh.topology.index_map(3).size_local)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(sys.argv[1], forces=np.array(forces), depths=np.array(depths), cells=np.array(cells))
