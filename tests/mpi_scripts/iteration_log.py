"""MPI helper of tests/integration/test_iteration_log.py: the pressed blocks (level 1) with the package's
logger at INFO on rank 0 only. Prints rank 0's committed plastic points of the last increment.
The iterative linear solver: Debian 13's MUMPS (no METIS) fails on this saddle-point matrix on
2 ranks (tests/integration/test_iterative.py)."""

import logging

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
from mpi4py import MPI

from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.solvers import MonolithicOptions, make_solver, solve_load_steps

if MPI.COMM_WORLD.rank == 0:
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    logging.getLogger("dolfinx_nnqem").setLevel(logging.INFO)
problem = pressed_blocks_problem(1, MPI.COMM_WORLD)
with make_solver("monolithic", problem, monolithic=MonolithicOptions(linear_solver="iterative")) as solver:
    results = solve_load_steps(problem, solver, 3, final_load_factor=0.5)
if MPI.COMM_WORLD.rank == 0:
    print(f"committed {results[-1].plastic_points} plastic points", flush=True)
