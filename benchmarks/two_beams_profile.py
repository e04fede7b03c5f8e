"""Profile of the two-beam benchmark: iterations, time split, JIT warm-up, memory, and the ratio

    total solve time / (iterations × one tangent factorisation + solve)

measured in the same run (issue: median ≤ 3 iterations per increment, ratio ≤ 2 once warm).

    python benchmarks/two_beams_profile.py [--method monolithic] [--increments 15] [--refine 1]

Prints figures; asserts nothing.
"""

import argparse
import platform
import resource
import statistics
import time

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import dolfinx
import numba
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.io import ResultsWriter
from dolfinx_nnqem.solvers import make_solver
from dolfinx_nnqem.solvers import solve_load_steps
from dolfinx_nnqem.cases.two_beams import DEFAULT_LAW, FREE_END_CORNERS, two_beams_problem


def one_tangent_solve(problem, solver) -> float:
    """Seconds for one assembly of the Newton matrix, one factorisation and one solve."""
    t0 = time.perf_counter()
    if solver.name == "monolithic":
        J = solver._newton_matrix(solver.evaluate())
    else:
        J = problem.assemble_tangent()
    ksp = PETSc.KSP().create(problem.comm)
    ksp.setOptionsPrefix("profile_")
    opts = PETSc.Options()
    for k, v in {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}.items():
        opts["profile_" + k] = v
    ksp.setFromOptions()
    ksp.setOperators(J)
    b = J.createVecRight()
    b.set(1.0)
    x = b.duplicate()
    ksp.solve(b, x)
    return time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--method", default="monolithic")
    parser.add_argument("--increments", type=int, default=15)
    parser.add_argument("--refine", type=int, default=1)
    parser.add_argument("--out", default="results/profile")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    law = DEFAULT_LAW[args.method]

    # 1. warm-up: form compilation (FFCx, cached on disk) and numba kernels (cached on disk)
    t0 = time.perf_counter()
    warm = two_beams_problem(comm, law=law, refine=args.refine)
    t_build_cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    with make_solver(args.method, warm) as solver:
        solve_load_steps(warm, solver, 1, final_load_factor=1.0 / args.increments)
    t_first_increment = time.perf_counter() - t0

    # 2. the measured run
    t0 = time.perf_counter()
    problem = two_beams_problem(comm, law=law, refine=args.refine)
    t_build = time.perf_counter() - t0
    solver = make_solver(args.method, problem)
    writer = ResultsWriter(problem, args.method, args.out, args.increments, probes=FREE_END_CORNERS)
    t0 = time.perf_counter()
    results = solve_load_steps(problem, solver, args.increments, callbacks=[writer])
    t_total = time.perf_counter() - t0
    writer.close()
    t_one = min(one_tangent_solve(problem, solver) for _ in range(3))

    iterations = [r.iterations for r in results]
    t_output = sum(r.output_time_s for r in results)
    t_commit = sum(r.commit_time_s for r in results)
    t_solve_only = t_total - t_output
    ratio = t_solve_only / (sum(iterations) * t_one)
    peak_mb = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, op=MPI.MAX)
    if comm.rank == 0:
        print(f"machine: {platform.processor() or platform.machine()}, {comm.size} rank(s); "
              f"DOLFINx {dolfinx.__version__}, PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}, "
              f"numba {numba.__version__}")
        print(f"method {args.method} (law {law}), refine {args.refine}: "
              f"{problem.V.dofmap.index_map.size_global * 3} displacement dofs, {problem.num_pairs} pairs")
        print(f"warm-up: first problem build {t_build_cold:.2f} s (JIT or disk cache), first increment "
              f"{t_first_increment:.2f} s; warm build {t_build:.2f} s")
        print(f"iterations per increment {iterations}; median {statistics.median(iterations)}; "
              f"total {sum(iterations)}")
        print(f"total {t_total:.2f} s = solve {t_solve_only:.2f} s + output {t_output:.2f} s; "
              f"state commit {t_commit:.2f} s")
        split = ", ".join(f"{k} {v:.2f} s" for k, v in sorted(solver.timings.items()))
        print(f"solver time split: {split}")
        print(f"one tangent assembly + factorisation + solve: {t_one * 1e3:.1f} ms")
        print(f"ratio solve / (iterations × one tangent solve) = {ratio:.2f}")
        print(f"peak memory (max over ranks): {peak_mb:.0f} MB")


if __name__ == "__main__":
    main()
