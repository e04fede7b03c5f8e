"""MPI helper of tests/integration/test_load_paths.py: every row of the load-path matrix, every method, in 1
and 4 increments, on the ranks it is started with.

    mpiexec -n 2 python load_paths.py OUT.json

Rank 0 writes, per cell "driver/increments/method": the support's contact force, the closed form
(or null), the largest p, the increments of first yield, the iterations, the cutbacks and the
worst constitutive relation of the independent check (in σ_u).
"""

import json
import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "integration"))  # the test module this script runs

from test_load_paths import ROWS, solve  # noqa: E402

from dolfinx_nnqem.solvers import METHODS  # noqa: E402

if __name__ == "__main__":
    cells = {}
    for driver in ROWS:
        for increments in (1, 4):
            for method in METHODS:
                run = solve(driver, method, increments)
                cells[f"{driver}/{increments}/{method}"] = {
                    "force": float(run["force"]), "exact": run["exact"], "p": run["p"],
                    "first_yield": run["first_yield"], "iterations": run["iterations"], "cutbacks": run["cutbacks"],
                    "worst_check": max(max(c.values()) for c in run["checks"])}
    if MPI.COMM_WORLD.rank == 0:
        Path(sys.argv[1]).write_text(json.dumps(cells, indent=1))
