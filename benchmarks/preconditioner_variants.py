"""Preconditioner variants of the iterative solver on one Newton system of the pressed blocks.

    python benchmarks/preconditioner_variants.py [--level 8] [--solve 9] [--forcing quadratic]

Runs the pressed blocks (monolithic, iterative) and, at the ``--solve``-th Newton solve, solves
that same augmented Newton system again with each variant of :data:`VARIANTS` (PETSc options
over the package's defaults): a fresh KSP and AMG hierarchy each, FGMRES (or the variant's
method) to 1e-6. Prints the Krylov iterations and the CPU seconds of the set-up and solve. One
system, so the counts compare preconditioners without the Newton path changing under them.
Asserts nothing.
"""

import argparse
import time

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
from mpi4py import MPI

from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.numerics.linalg import (ITERATIVE_SOLVER_OPTIONS, clear_options, create_ksp,
                                           products_without_intermediates)
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions, solve_load_steps
from dolfinx_nnqem.solvers import linear_solver
from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.solvers.options import FORCING_RULES

VARIANTS = {
    "defaults": {},
    "Chebyshev 3 steps": {"fieldsplit_u_mg_levels_ksp_max_it": 3},
    "Chebyshev 1 step": {"fieldsplit_u_mg_levels_ksp_max_it": 1},
    "no aggressive coarsening": {"fieldsplit_u_pc_gamg_aggressive_coarsening": 0},
    "threshold 0.0": {"fieldsplit_u_pc_gamg_threshold": 0.0},
    "threshold 0.05": {"fieldsplit_u_pc_gamg_threshold": 0.05},
    "full Schur factorisation": {"pc_fieldsplit_schur_fact_type": "full"},
    "GMRES, right": {"ksp_type": "gmres", "ksp_pc_side": "right"},
    "two V-cycles": {"fieldsplit_u_ksp_type": "richardson", "fieldsplit_u_ksp_max_it": 2},
    "plain aggregation": {"fieldsplit_u_pc_gamg_agg_nsmooths": 0},
    "no SA eigenvalue estimate": {"fieldsplit_u_pc_gamg_use_sa_esteig": "false"},
}


def compare_variants(J, b, x, comm, tag: str) -> None:
    """Solve J y = b with every variant; print iterations and CPU seconds."""
    (is_u, is_z), _ = J.getNestISs()  # the near-nullspace is already composed on is_u
    for name, extra in VARIANTS.items():
        options = {**ITERATIVE_SOLVER_OPTIONS, **extra, "ksp_rtol": 1e-6, "ksp_max_it": 300}
        prefix = f"variant_{tag}_{len(name)}_{abs(hash(name))}_"
        ksp = create_ksp(comm, prefix, options)
        ksp.getPC().setFieldSplitIS(("u", is_u), ("z", is_z))
        ksp.setOperators(J)
        y = x.duplicate()
        comm.Barrier()
        c0 = time.process_time()
        with products_without_intermediates():
            ksp.solve(b, y)  # the set-up of the u block's AMG happens inside
        cpu = comm.allreduce(time.process_time() - c0, op=MPI.MAX)
        if comm.rank == 0:
            print(f"  {name:28s} Krylov {ksp.getIterationNumber():4d} (reason {ksp.getConvergedReason()}), "
                  f"CPU {cpu:6.2f} s", flush=True)
        clear_options(prefix, options)
        ksp.destroy()
        y.destroy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--level", type=int, default=8)
    parser.add_argument("--solve", type=int, default=9, help="which Newton solve of the load path (1-based)")
    parser.add_argument("--forcing", choices=FORCING_RULES, default="eisenstat-walker",
                        help="the inexact-Newton rule of the load path up to that solve")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    count = [0]
    solve = linear_solver.IterativeSolver.solve

    def solve_and_compare(self, J, b, x, pair_state=None):
        why_not = solve(self, J, b, x, pair_state)
        count[0] += 1
        if count[0] == args.solve:
            if comm.rank == 0:
                print(f"Newton solve {count[0]} of the pressed blocks, level {args.level}:", flush=True)
            compare_variants(J, b, x, comm, str(count[0]))
        return why_not

    linear_solver.IterativeSolver.solve = solve_and_compare  # type: ignore[method-assign]
    problem = pressed_blocks_problem(args.level, comm)
    with MonolithicSolver(problem, SolverOptions(max_iterations=40),
                          MonolithicOptions(linear_solver="iterative", forcing=args.forcing)) as solver:
        solve_load_steps(problem, solver, 6)


if __name__ == "__main__":
    main()
