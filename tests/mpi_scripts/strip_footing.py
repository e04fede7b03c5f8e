"""MPI helper of tests/integration/test_strip_footing.py: the rough footing on Drucker–Prager (φ = 20°), n = 1.

    mpiexec -n N python strip_footing.py OUT.npz

Rank 0 writes the footing pressure after each increment and the number of cells each rank owns.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))  # the test module this script runs

from test_strip_footing import case, footing_run  # noqa: E402

if __name__ == "__main__":
    pressures, problem = footing_run(case.drucker_prager_soil(20.0), footing="rough", comm=MPI.COMM_WORLD)
    cells = MPI.COMM_WORLD.gather(problem.mesh.topology.index_map(3).size_local)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(sys.argv[1], pressures=pressures, cells=np.array(cells))
