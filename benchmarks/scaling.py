"""Scaling of the monolithic solver: two elastoplastic blocks pressed together, refined ×k.

    python benchmarks/scaling.py --levels 1 2 4 --linear-solver direct iterative
    mpiexec -n 2 python benchmarks/scaling.py --levels 4

Body 1 (1 × 0.5 × 1, bottom clamped) carries body 2 (1 × 0.5 × 1), pressed on top by a pressure
above the yield stress and dragged sideways by a prescribed displacement of its top (u_z = 0 on the
z faces); node-to-node pairs on the whole interface (the V5 set-up, elastoplastic). The pressure
rises over the first half of the load factor, the drag over the second. Level k has 4k × 2k × 4k hexahedra per
block. Prints, per level and linear solver: displacement dofs, pairs, Newton iterations, time per
iteration, the time split, peak memory, and the ratio time / (iterations × one Newton solve).
Asserts nothing.
"""

import argparse
import resource
import time

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import numpy as np
from mpi4py import MPI

from dolfinx_nnqem.material import VonMises
from dolfinx_nnqem.meshing import StackedBlocksTags as T
from dolfinx_nnqem.meshing import build_stacked_blocks
from dolfinx_nnqem.monolithic import MonolithicSolver
from dolfinx_nnqem.problem import Contact, ContactProblem, Dirichlet, Pressure, SolverOptions
from dolfinx_nnqem.stepping import solve_load_steps

MU_F = 0.3
MATERIAL = VonMises(E=2.0e10, nu=0.2, sigma_y0=2.0e7, H=2.0e9)


def blocks_problem(level: int, comm) -> ContactProblem:
    n = 4 * level
    mesh, ct, ft = build_stacked_blocks(comm, 1.0, 0.5, 0.5, 1.0, n, 2 * level, 2 * level, n)
    return ContactProblem(
        mesh, ct, ft, materials={T.BODY1: MATERIAL, T.BODY2: MATERIAL},
        dirichlet=[Dirichlet(T.BOTTOM), Dirichlet(T.TOP, 2.0e-3, [0], amplitude=lambda ell: max(2 * ell - 1, 0.0)),
                   Dirichlet(T.BODY1_ZMIN, 0.0, [2]), Dirichlet(T.BODY1_ZMAX, 0.0, [2]),
                   Dirichlet(T.BODY2_ZMIN, 0.0, [2]), Dirichlet(T.BODY2_ZMAX, 0.0, [2])],
        tractions=[Pressure(T.TOP, 3.0e7, amplitude=lambda ell: min(2 * ell, 1.0))],
        contact=Contact(T.CONTACT1, T.CONTACT2, mu_f=MU_F),
    )


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--linear-solver", nargs="+", default=["direct", "iterative"])
    parser.add_argument("--increments", type=int, default=6)
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    rank0 = comm.rank == 0
    if rank0:
        print(f"{comm.size} rank(s); {args.increments} increments per run")
        print(f"{'level':>5} {'solver':>9} {'dofs':>9} {'pairs':>6} {'its':>4} {'s/it':>7} {'total s':>8} "
              f"{'assembly':>8} {'contact':>8} {'blocks':>8} {'solve':>8} {'MB':>6}")
    for level in args.levels:
        for linear_solver in args.linear_solver:
            t0 = time.perf_counter()
            problem = blocks_problem(level, comm)
            t_setup = time.perf_counter() - t0
            solver = MonolithicSolver(problem, SolverOptions(linear_solver=linear_solver, max_iterations=40))
            t0 = time.perf_counter()
            results = solve_load_steps(problem, solver, args.increments)
            total = time.perf_counter() - t0
            its = sum(r.iterations for r in results)
            mb = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, op=MPI.MAX)
            t = solver.timings
            if rank0:
                print(f"{level:>5} {linear_solver:>9} {problem.V.dofmap.index_map.size_global * 3:>9} "
                      f"{problem.num_pairs:>6} {its:>4} {total / max(its, 1):>7.2f} {total:>8.2f} "
                      f"{t.get('assembly', 0):>8.2f} {t.get('contact', 0):>8.2f} {t.get('block_matrix', 0):>8.2f} "
                      f"{t.get('solve', 0):>8.2f} {mb:>6.0f}   (setup {t_setup:.1f} s, "
                      f"iterations {[r.iterations for r in results]})", flush=True)


if __name__ == "__main__":
    main()
