"""MPI helper of tests/integration/test_iterative.py: the pressed blocks (level 2, or LEVEL) solved by the monolithic solver.

    mpiexec -n N python pressed_blocks.py LINEAR_SOLVER OUT.npz [LEVEL]

Rank 0 writes the pair positions, the pair forces on body 1 and the displacements of body 2's
pair nodes (gathered, in the global pair order) and the Newton iterations per increment. At the
end every rank prints PETSc's garbage list of each of the problem's communicators ("Total
entries: N"): objects dropped by the solver and never destroyed would be listed there.
"""

import sys

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.solvers import MonolithicOptions
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import solve_load_steps

linear_solver, out = sys.argv[1], sys.argv[2]
problem = pressed_blocks_problem(int(sys.argv[3]) if len(sys.argv) > 3 else 2, MPI.COMM_WORLD)
results = solve_load_steps(problem, MonolithicSolver(problem, monolithic=MonolithicOptions(linear_solver=linear_solver)), 6)
table = pair_table(problem)
if MPI.COMM_WORLD.rank == 0:
    np.savez(out, position=table["position"], force_on_body1=table["force_on_body1"],
             u_body2=table["u_body2"], iterations=[r.iterations for r in results])
for comm in problem.petsc_comms:
    PETSc.garbage_view(comm)
