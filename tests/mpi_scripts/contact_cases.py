"""MPI helper of tests/test_contact_mpi.py: a contact case solved on any number of ranks.

    mpiexec -n N python contact_cases.py CASE METHOD OUT.npz

CASE: "three_blocks" (two interfaces, the drag making the lower one slide) or "sphere" (a rigid
sphere pressed on a graded block, then sliding sideways). Rank 0 writes the pair table's slave
positions, interfaces, forces on body 1 and slave displacements (global pair order) and the
iterations per increment.
"""

import sys
from pathlib import Path

import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel loads MPI/PETSc before dolfinx)
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dolfinx_nnqem.results import pair_table  # noqa: E402
from dolfinx_nnqem.solver import SolverOptions, make_solver  # noqa: E402
from dolfinx_nnqem.stepping import solve_load_steps  # noqa: E402


def solve_case(case: str, method: str, comm=MPI.COMM_WORLD) -> dict:
    if case == "three_blocks":
        from test_interfaces import three_blocks

        problem, increments = three_blocks(mu_f=(0.2, 0.4), drag=1.0e-2, comm=comm), 10
    elif case == "sphere":
        from test_obstacles import sphere_problem_sliding

        problem, increments = sphere_problem_sliding(comm), 4
    else:
        raise ValueError(f"unknown case {case!r}")
    solver = make_solver(method, problem, SolverOptions(rtol=1e-12, max_iterations=40))
    results = solve_load_steps(problem, solver, increments)
    t = pair_table(problem)
    return {"position": t["position_b"], "interface": t["interface"], "force": t["force_on_body1"],
            "u": t["u_body2"], "iterations": np.array([r.iterations for r in results])}


if __name__ == "__main__":
    case, method, out = sys.argv[1:4]
    data = solve_case(case, method)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, **data)
