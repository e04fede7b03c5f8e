"""Scaling of the monolithic solver on the pressed blocks (``dolfinx_nnqem.cases.pressed_blocks``).

    python benchmarks/scaling.py --levels 1 2 4 --linear-solver direct iterative
    python benchmarks/scaling.py --levels 10 --linear-solver iterative --save run1.npz
    mpiexec -n 2 python benchmarks/scaling.py --levels 10 --linear-solver iterative --save run2.npz
    python benchmarks/scaling.py --compare run1.npz run2.npz
    mpiexec -n 2 python benchmarks/scaling.py --levels 17 --linear-solver iterative
    mpiexec -n 2 python benchmarks/scaling.py --levels 17 --linear-solver iterative --increments 2 --final-load-factor 0.5
    mpiexec -n 2 python benchmarks/scaling.py --levels 8 --linear-solver iterative --forcing quadratic

Two elastoplastic blocks pressed together, then dragged; level k has 4k × 2k × 4k hexahedra
per block (level 17: 1.0e6 displacement dofs). Per level and linear solver it prints the
displacement dofs, pairs, Newton iterations per increment, Krylov iterations, seconds per
Newton iteration (and per iteration and 10⁵ dofs, to judge linearity), the time split, the
peak memory (largest rank and the sum over ranks) over the load path and again after the
reference solve below (its FGMRES basis and fresh hierarchy can raise it), and the ratio

    solve time / (Newton iterations × one Newton-matrix build + preconditioner set-up + solve)

with that one solve measured in the same run (MUMPS: a factorisation; iterative: a fresh
AMG hierarchy and a Krylov solve to 1e-8). JIT warm-up (FFCx forms, numba kernels; both cached
on disk, so a second run pays only the cache loading) is measured first, on level 1, and
reported separately. ``--save`` writes the pair forces and displacements (gathered, with
positions) so that runs on different numbers of ranks can be compared with ``--compare``.
Asserts nothing.
"""

import argparse
import json
import platform
import resource
import time

import dolfinx_nnqem  # noqa: F401  (before dolfinx)
import dolfinx
import numba
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_nnqem.solvers.monolithic import MonolithicSolver
from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
from dolfinx_nnqem.solvers import MonolithicOptions, SolverOptions
from dolfinx_nnqem.solvers.options import FORCING_RULES
from dolfinx_nnqem.io import pair_table
from dolfinx_nnqem.solvers import solve_load_steps


def peak_memory_mb(comm) -> tuple[float, float]:
    """(largest rank, sum over ranks) of the peak resident memory, MB."""
    mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return comm.allreduce(mb, op=MPI.MAX), comm.allreduce(mb, op=MPI.SUM)


def one_newton_solve(problem, solver) -> float:
    """Seconds for one Newton matrix build, a fresh preconditioner (or factorisation) and one solve.

    Uses the solver's own KSP (no second AMG hierarchy in memory); iterative: to rtol 1e-8.
    """
    comm = problem.comm
    evaluation = solver.evaluate()
    solver.linear._refresh = True  # a fresh AMG hierarchy (iterative) or factorisation (direct)
    if solver.iterative:
        solver.linear.ksp.setTolerances(rtol=1e-8)
    comm.Barrier()
    t0 = time.perf_counter()
    solver.newton_direction(evaluation)
    comm.Barrier()
    return time.perf_counter() - t0


def run(level: int, linear_solver: str, increments: int, final_load_factor: float, comm,
        petsc_options: dict | None = None, monolithic: dict | None = None) -> dict:
    comm.Barrier()
    t0 = time.perf_counter()
    problem = pressed_blocks_problem(level, comm)
    t_setup = time.perf_counter() - t0
    solver = MonolithicSolver(problem, SolverOptions(max_iterations=40, petsc_options=petsc_options or {}),
                              MonolithicOptions(linear_solver=linear_solver, **(monolithic or {})))
    comm.Barrier()
    t0, c0 = time.perf_counter(), time.process_time()
    results = solve_load_steps(problem, solver, increments, final_load_factor=final_load_factor)
    t_total = time.perf_counter() - t0
    cpu_total = comm.allreduce(time.process_time() - c0, op=MPI.MAX)  # a shared machine's load inflates wall time more
    t_commit = sum(r.commit_time_s for r in results)
    iterations = [r.iterations for r in results]
    amg_setups = solver.amg_setups
    mem_max, mem_sum = peak_memory_mb(comm)  # the load path's (what a user's run needs)
    t_one = one_newton_solve(problem, solver)
    mem_max_ref, mem_sum_ref = peak_memory_mb(comm)  # with the reference solve (to 1e-8, a fresh hierarchy)
    table = pair_table(problem)
    dofs = problem.V.dofmap.index_map.size_global * 3
    its = max(sum(iterations), 1)
    return {
        "level": level, "ranks": comm.size, "linear_solver": linear_solver, "petsc_options": petsc_options or {},
        "monolithic": monolithic or {},
        "dofs": dofs,
        "pairs": problem.num_pairs, "iterations": iterations, "krylov": solver.linear_iterations,
        "lm_steps": sum(h.kind == "lm" for r in results for h in r.report.history),
        "amg_setups": amg_setups,
        "setup_s": t_setup, "total_s": t_total, "cpu_s": cpu_total, "commit_s": t_commit,
        "split_s": {k: comm.allreduce(v, op=MPI.MAX) for k, v in solver.timings.items()},
        "s_per_iteration": t_total / its, "s_per_iteration_per_1e5_dofs": t_total / its / (dofs / 1e5),
        "one_newton_solve_s": t_one, "ratio": (t_total - t_commit) / (its * t_one),
        "memory_mb_max_rank": mem_max, "memory_mb_sum": mem_sum,
        "memory_mb_max_rank_with_reference": mem_max_ref, "memory_mb_sum_with_reference": mem_sum_ref,
        "slipping_pairs": int(np.count_nonzero(table["state"] == 2)),
        "plastic_points": problem.state.count_plastic_points(),
        "_table": {"position": table["position"], "force_on_body1": table["force_on_body1"],
                   "u_body2": table["u_body2"]},
    }


def compare(file_a: str, file_b: str) -> None:
    """Largest relative differences of pair forces and displacements between two saved runs."""
    a, b = np.load(file_a), np.load(file_b)
    order = lambda x: np.lexsort((x[:, 2], x[:, 1], x[:, 0]))  # noqa: E731  (pairs by position)
    i, j = order(a["position"].round(9)), order(b["position"].round(9))
    for key in ("force_on_body1", "u_body2"):
        ref = a[key][i]
        print(f"{key}: max |{file_b} − {file_a}| / max |{file_a}| = "
              f"{np.abs(b[key][j] - ref).max() / np.abs(ref).max():.2e}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--linear-solver", nargs="+", default=["direct", "iterative"])
    parser.add_argument("--increments", type=int, default=6)
    parser.add_argument("--final-load-factor", type=float, default=1.0)
    parser.add_argument("--save", help="write the last run's pair forces and displacements (.npz)")
    parser.add_argument("--json", help="append the figures of every run to this JSON-lines file")
    parser.add_argument("--compare", nargs=2, metavar=("A.npz", "B.npz"))
    parser.add_argument("--petsc-option", action="append", default=[], metavar="KEY=VALUE",
                        help="a PETSc option of the linear solver, without prefix (repeatable), e.g. "
                             "fieldsplit_u_pc_gamg_threshold=0.02")
    parser.add_argument("--forcing", choices=FORCING_RULES, help="MonolithicOptions.forcing (default: the package's)")
    parser.add_argument("--max-forcing", type=float, help="MonolithicOptions.max_forcing (default: the package's)")
    args = parser.parse_args()
    petsc_options = dict(o.split("=", 1) for o in args.petsc_option)
    monolithic = {k: v for k, v in (("forcing", args.forcing), ("max_forcing", args.max_forcing)) if v is not None}
    if args.compare:
        compare(*args.compare)
        return
    comm = MPI.COMM_WORLD
    rank0 = comm.rank == 0

    # JIT warm-up on level 1: FFCx forms and numba kernels (both cached on disk)
    t0 = time.perf_counter()
    warm = pressed_blocks_problem(1, comm)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    # with the first linear solver asked for: MUMPS on 2 ranks fails on level 1 in most runs
    # (the first Newton matrix is singular while every pair is open; docs/performance.md)
    with MonolithicSolver(warm, monolithic=MonolithicOptions(linear_solver=args.linear_solver[0])) as solver:
        solve_load_steps(warm, solver, 1, final_load_factor=1.0 / args.increments)
    t_first = time.perf_counter() - t0
    if rank0:
        print(f"machine: {platform.machine()}, {comm.size} rank(s); DOLFINx {dolfinx.__version__}, "
              f"PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}, numba {numba.__version__}")
        print(f"JIT warm-up (level 1): problem build {t_build:.2f} s, first increment {t_first:.2f} s")
        print(f"{args.increments} increments to load factor {args.final_load_factor}")
    last = None
    for level in args.levels:
        for linear_solver in args.linear_solver:
            r = run(level, linear_solver, args.increments, args.final_load_factor, comm, petsc_options, monolithic)
            last = r
            if not rank0:
                continue
            split = ", ".join(f"{k} {v:.1f}" for k, v in sorted(r["split_s"].items()))
            print(f"\nlevel {level}, {linear_solver}, {comm.size} rank(s): {r['dofs']} dofs, {r['pairs']} pairs; "
                  f"set-up {r['setup_s']:.1f} s")
            print(f"  Newton iterations {r['iterations']} (total {sum(r['iterations'])}, {r['lm_steps']} LM steps), "
                  f"Krylov {r['krylov']}, AMG set-ups {r['amg_setups']}; "
                  f"slipping pairs at the end {r['slipping_pairs']}, plastic Gauss points {r['plastic_points']}")
            print(f"  total {r['total_s']:.1f} s (CPU {r['cpu_s']:.1f} s on the busiest rank; state commit "
                  f"{r['commit_s']:.1f} s); {r['s_per_iteration']:.2f} s "
                  f"per Newton iteration = {r['s_per_iteration_per_1e5_dofs']:.2f} s per 1e5 dofs")
            print(f"  split (s): {split}")
            print(f"  one Newton solve {r['one_newton_solve_s']:.2f} s; ratio solve / (iterations × one) "
                  f"= {r['ratio']:.2f}")
            print(f"  peak memory over the load path: {r['memory_mb_max_rank']:.0f} MB (largest rank), "
                  f"{r['memory_mb_sum']:.0f} MB (all ranks); with the reference solve: "
                  f"{r['memory_mb_max_rank_with_reference']:.0f} MB, {r['memory_mb_sum_with_reference']:.0f} MB",
                  flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps({k: v for k, v in r.items() if k != "_table"}) + "\n")
    if args.save and rank0 and last is not None:
        np.savez(args.save, **last["_table"])


if __name__ == "__main__":
    main()
