"""The seed's methods at scale: NNEQM1 and NNEQM2 against the monolithic solver on the pressed blocks.

NNEQM1 condenses every outer iteration onto the pairs: one factorisation of the tangent, 3NC
solves for X = G Bᵀ and the dense flexibility C = B X (3NC × 3NC), then a dense nonsmooth solve.
NNEQM2's default ("return-map") variant does the same per Newton step (and factorises the
elastic stiffness once). Each (level, method) runs in its own process, so that its peak memory
is its own; the script prints the displacement dofs, pairs, iterations, wall and CPU time, peak
memory, the memory the dense condensation needs (:func:`dolfinx_nnqem.solvers.condensation.dense_memory`)
and where the time goes (the solvers' ``timings``). Prints figures; asserts nothing::

    python benchmarks/dense_methods.py --levels 4 --methods monolithic nneqm1 nneqm2
    python benchmarks/dense_methods.py --levels 8 --methods nneqm1 --increments 6 --final-load-factor 0.1667
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time


def one(level: int, method: str, increments: int, final_load_factor: float) -> dict:
    """Solve the pressed blocks of ``level`` with ``method`` in this process; the figures."""
    import dolfinx_nnqem  # noqa: F401  (first: the PyPI wheel)
    from mpi4py import MPI

    from dolfinx_nnqem.cases.pressed_blocks import pressed_blocks_problem
    from dolfinx_nnqem.solvers import ConvergenceError, SolverOptions, make_solver, solve_load_steps
    from dolfinx_nnqem.solvers.condensation import available_memory, dense_memory

    t0 = time.perf_counter()
    problem = pressed_blocks_problem(level, MPI.COMM_WORLD)
    setup = time.perf_counter() - t0
    need = sum(dense_memory(problem).values())
    out = {"level": level, "method": method, "dofs": 3 * problem.V.dofmap.index_map.size_global,
           "pairs": problem.num_pairs, "setup_s": setup, "dense_memory_gb": need / 1e9,
           "available_gb": (available_memory() or float("nan")) / 1e9}
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with make_solver(method, problem, SolverOptions(max_iterations=40)) as solver:
            try:
                results = solve_load_steps(problem, solver, increments, final_load_factor=final_load_factor)
                out["iterations"] = [r.iterations for r in results]
                out["converged"] = True
            except ConvergenceError as error:
                out["converged"], out["error"] = False, str(error).splitlines()[0]
            out["timings_s"] = {k: round(v, 2) for k, v in solver.timings.items()}
    except ValueError as error:  # refused before solving (memory)
        out["refused"] = str(error)
    out["total_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[4])
    parser.add_argument("--methods", nargs="+", default=["monolithic", "nneqm1", "nneqm2"])
    parser.add_argument("--increments", type=int, default=6)
    parser.add_argument("--final-load-factor", type=float, default=1.0)
    parser.add_argument("--json", help="append each run's figures to this JSON-lines file")
    parser.add_argument("--one", nargs=2, metavar=("LEVEL", "METHOD"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one(int(args.one[0]), args.one[1], args.increments, args.final_load_factor)))
        return
    for level in args.levels:
        for method in args.methods:
            run = subprocess.run([sys.executable, __file__, "--one", str(level), method, "--increments",
                                  str(args.increments), "--final-load-factor", str(args.final_load_factor)],
                                 capture_output=True, text=True)
            lines = [line for line in run.stdout.splitlines() if line.startswith("{")]
            if not lines:
                print(f"level {level}, {method}: the run failed (exit {run.returncode}): "
                      f"{(run.stderr.strip().splitlines() or ['?'])[-1]}", flush=True)
                continue
            r = json.loads(lines[-1])
            print(f"\nlevel {level}, {method}: {r['dofs']} dofs, {r['pairs']} pairs; dense condensation "
                  f"{r['dense_memory_gb']:.2f} GB (available {r['available_gb']:.1f} GB)")
            if "refused" in r:
                print(f"  refused before solving: {r['refused']}")
            else:
                print(f"  iterations {r.get('iterations')}{'' if r.get('converged') else ' NOT CONVERGED: ' + r.get('error', '')}")
                print(f"  total {r['total_s']:.1f} s, CPU {r['cpu_s']:.1f} s, peak memory {r['peak_mb']:.0f} MB")
                print(f"  split (s): {', '.join(f'{k} {v:.1f}' for k, v in sorted(r['timings_s'].items()))}", flush=True)
            if args.json:
                with open(args.json, "a") as fh:
                    fh.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    main()
