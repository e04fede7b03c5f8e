"""MPI helper of tests/integration/test_parameter_update.py: the two beams solved, updated (μ_f = 0.2 and beam
2's E = 3e10 Pa) and solved again, against the same problem built afresh, on the ranks it is
started with (update is collective: the moduli, r and the rigid-mode checks are reduced over ranks).

    mpiexec -n 2 python parameter_update.py OUT.json

Rank 0 writes, per method, the largest difference of u over all ranks relative to the largest |u|.
"""

import dataclasses
import json
import sys

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.cases.two_beams import MATERIAL, two_beams_problem
from dolfinx_nnqem.problem import ContactProblem
from dolfinx_nnqem.cases.geometries import TwoBeamsTags as T
from dolfinx_nnqem.solvers.registry import make_solver
from dolfinx_nnqem.solvers.stepping import solve_load_steps


def solve(problem: ContactProblem, method: str) -> None:
    with make_solver(method, problem) as solver:
        solve_load_steps(problem, solver, 4)


def updated_against_fresh(method: str, comm: MPI.Comm) -> float:
    problem = two_beams_problem(comm)
    solve(problem, method)
    problem.update(mu_f=0.2, materials={T.BODY2: dataclasses.replace(MATERIAL, E=3e10)})
    solve(problem, method)
    d = problem.definition
    fresh = ContactProblem(problem.mesh, problem.cell_tags, problem.facet_tags, materials=d.materials,
                           dirichlet=d.dirichlet, tractions=d.tractions, body_forces=d.body_forces,
                           contact=list(d.contact))
    solve(fresh, method)
    diff = comm.allreduce(float(np.abs(problem.u.x.array - fresh.u.x.array).max()), op=MPI.MAX)
    return diff / comm.allreduce(float(np.abs(fresh.u.x.array).max()), op=MPI.MAX)


if __name__ == "__main__":
    comm = MPI.COMM_WORLD
    found = {method: updated_against_fresh(method, comm) for method in ("monolithic", "nneqm1")}
    if comm.rank == 0:
        with open(sys.argv[1], "w") as f:
            json.dump({"ranks": comm.size, **found}, f)
